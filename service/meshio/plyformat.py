"""The PLY file's structure: its header (the format, the elements and their properties) and
its rows, found and read a batch at a time, binary (one numpy pass per batch of rows of one
shape, the rows' list sizes walked where shapes differ) and ASCII. :mod:`.ply` turns them
into a mesh.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from .mesh import MeshFormatError
from .text import LF, Lines, chunks, count_lines, parse_numbers, positions, token_starts

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
MAX_CORNERS = 255  # a polygon with more is surely a misread list
#: Runs of rows of one shape shorter than this are walked with their neighbours.
_MIN_RUN = 16


@dataclass(frozen=True)
class Property:
    name: str
    type: str  # numpy kind code, e.g. "f4"
    count_type: str | None = None  # set for a list property


@dataclass(frozen=True)
class Element:
    name: str
    count: int
    properties: tuple[Property, ...]
    max_items: int = MAX_CORNERS  # the longest list a row may hold

    @property
    def fixed(self) -> bool:
        return all(p.count_type is None for p in self.properties)

    @property
    def lists(self) -> list[Property]:
        return [p for p in self.properties if p.count_type is not None]


@dataclass(frozen=True)
class Batch:
    """Rows ``[row, row + rows)`` of an element, in bytes ``[begin, end)``: binary rows of
    one ``shape`` (their list sizes), binary rows of several (``counts``: each list's sizes,
    one a row), or ASCII rows (neither)."""

    row: int
    rows: int
    begin: int
    end: int
    shape: tuple[int, ...] | None = None
    counts: tuple[np.ndarray, ...] | None = None


# -- header ---------------------------------------------------------------------------------


def header(data: bytes | memoryview) -> tuple[str | None, list[Element], int]:
    """The byte order (None for ASCII), the elements, and where the body starts."""
    lines, body = _header_lines(bytes(data[: 1 << 16]))
    order, elements = None, []
    seen_format = False
    for number, line in enumerate(lines, 1):
        words = line.split()
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3 and words[1] in _FORMATS:
            order, seen_format = _FORMATS[words[1]], True
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            if any(element.name == words[1] for element in elements):
                raise MeshFormatError(f"PLY header line {number}: a second {words[1]!r} element")
            elements.append(Element(words[1], int(words[2]), ()))
        elif words[0] == "property" and elements:
            elements[-1] = _with_property(elements[-1], words, number)
        else:
            raise MeshFormatError(f"PLY header line {number} is not understood: {line!r}")
    if not seen_format:
        raise MeshFormatError("the PLY header has no 'format ascii|binary_... 1.0' line")
    return order, elements, body


def _header_lines(head: bytes) -> tuple[list[str], int]:
    """The header's lines before ``end_header`` (``head``: the file's first 64 KiB), and
    where the body starts."""
    if not head.startswith(b"ply"):
        raise MeshFormatError("not a PLY file: it does not start with 'ply'")
    lines, offset = [], 0
    while offset < len(head):
        newline = head.find(b"\n", offset)
        if newline < 0:
            break
        line = head[offset:newline].decode("ascii", "replace").strip()
        offset = newline + 1
        if line == "end_header":
            return lines, offset
        lines.append(line)
    raise MeshFormatError("not a PLY file: no 'end_header' line within its first 64 KiB")


def _with_property(element: Element, words: list[str], number: int) -> Element:
    """``element`` with the property of header line ``number`` added."""
    new = _prop(words)
    if any(p.name == new.name for p in element.properties):
        raise MeshFormatError(
            f"PLY header line {number}: {element.name!r} has a second {new.name!r} property"
        )
    return Element(element.name, element.count, (*element.properties, new))


def _prop(words: list[str]) -> Property:
    if len(words) == 3 and words[1] in _TYPES:
        return Property(words[2], _TYPES[words[1]])
    if len(words) == 5 and words[1] == "list" and words[2] in _TYPES and words[3] in _TYPES:
        if _TYPES[words[2]][0] == "f":
            raise MeshFormatError(f"PLY list {words[4]!r} counts with a float type")
        return Property(words[4], _TYPES[words[3]], _TYPES[words[2]])
    raise MeshFormatError(f"PLY property line not understood: {' '.join(words)!r}")


# -- binary ---------------------------------------------------------------------------------

_STRUCT = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I"}


def binary_batches(
    buffer: np.ndarray,
    position: int,
    element: Element,
    order: str,
    chunk_bytes: int,
    batch_rows: int,
):
    """The batches of an element's rows from ``position``, each at most ``batch_rows`` rows
    in about ``chunk_bytes``, and where the element ends."""
    if element.count == 0:
        return [], position
    if element.fixed:
        size = _row_dtype(element, order, ()).itemsize
        end = position + size * element.count
        if end > len(buffer):
            raise _short(element, len(buffer) - position, end - position)
        per = max(1, min(batch_rows, chunk_bytes // max(size, 1)))
        rows = [(row, min(per, element.count - row)) for row in range(0, element.count, per)]
        begin = position
        return [
            Batch(row, n, begin + row * size, begin + (row + n) * size, shape=()) for row, n in rows
        ], end
    smallest = sum(np.dtype(p.count_type or p.type).itemsize for p in element.properties)
    if position + smallest * element.count > len(buffer):
        raise _short(element, len(buffer) - position, smallest * element.count)
    return _Walker(buffer, element, order, position, chunk_bytes, batch_rows).batches()


class _Walker:
    """Finds the rows of an element with lists, batch by batch: a run of rows of one shape
    is checked in one numpy pass; rows of mixed shapes are walked one by one, reading only
    their list sizes."""

    def __init__(
        self,
        buffer: np.ndarray,
        element: Element,
        order: str,
        start: int,
        chunk_bytes: int,
        batch_rows: int,
    ) -> None:
        self.buffer, self.element, self.order, self.start = buffer, element, order, start
        self.chunk_bytes, self.batch_rows = chunk_bytes, batch_rows
        self.view = memoryview(buffer)
        self.plan = [
            (p, np.dtype(p.type).itemsize, None)
            if p.count_type is None
            else (p, np.dtype(p.type).itemsize, struct.Struct(order + _STRUCT[p.count_type]))
            for p in element.properties
        ]
        self.count_types = [np.dtype(p.count_type) for p in element.lists]

    def batches(self) -> tuple[list[Batch], int]:
        element, position, row, out = self.element, self.start, 0, []
        while row < element.count:
            counts, stop = self.walk(position, row, 1, 0)
            shape, size, left = tuple(c[0] for c in counts), stop - position, element.count - row
            run = self.run(
                position, shape, size, max(1, min(self.batch_rows, left, self.chunk_bytes // size))
            )
            if run >= min(_MIN_RUN, left):
                out.append(Batch(row, run, position, position + run * size, shape=shape))
                row, position = row + run, position + run * size
                continue
            counts, stop = self.walk(position, row, min(self.batch_rows, left), self.chunk_bytes)
            sizes = tuple(
                np.frombuffer(c, dtype=np.uint8) if isinstance(c, bytearray) else np.asarray(c, t)
                for c, t in zip(counts, self.count_types, strict=True)
            )
            out.append(Batch(row, len(counts[0]), position, stop, counts=sizes))
            row, position = row + len(counts[0]), stop
        return out, position

    def run(self, position: int, shape: tuple, size: int, rows: int) -> int:
        """How many of the ``rows`` rows from ``position`` have the list sizes ``shape``
        (``size`` bytes each), the first of which has (one numpy pass)."""
        rows = min(rows, (len(self.buffer) - position) // size)
        same = np.ones(rows, dtype=bool)
        for k, (p, at) in enumerate(_count_offsets(self.element, shape)):
            dtype = np.dtype(self.order + p.count_type)
            counts = np.ndarray((rows,), dtype, self.buffer, position + at, (size,))
            same &= counts == shape[k]
        return rows if same.all() else int(np.argmin(same))

    def walk(self, position: int, row: int, rows: int, budget: int) -> tuple[list, int]:
        """The list sizes of up to ``rows`` rows from ``position`` (fewer once they span
        ``budget`` bytes), a sequence for each list, and where the last one ends."""
        lists = self.element.lists
        if len(lists) == 1 and np.dtype(lists[0].count_type).itemsize == 1:
            counts, offset = self._walk_bytes(position, row, rows, position + budget)
        else:
            counts, offset = self._walk_any(position, row, rows, position + budget)
        if offset > len(self.buffer):
            raise _short(self.element, len(self.buffer) - self.start, offset - self.start)
        return counts, offset

    def _walk_bytes(self, offset: int, row: int, rows: int, limit: int):
        """:meth:`walk` for rows with one list counted in a byte (the usual face): a few
        Python operations a row."""
        element, view, end = self.element, self.view, len(self.buffer)
        (p,) = element.lists
        before = sum(
            np.dtype(q.type).itemsize for q in element.properties[: element.properties.index(p)]
        )
        fixed = sum(np.dtype(q.count_type or q.type).itemsize for q in element.properties)
        item, signed, most = np.dtype(p.type).itemsize, p.count_type == "i1", element.max_items
        counts = bytearray()
        for number in range(row, row + rows):
            if offset + before >= end:
                raise _short(element, end - self.start, offset + before + 1 - self.start)
            n = view[offset + before]
            if n > most or (signed and n > 127):
                raise self._too_many(number, p, n - 256 if signed and n > 127 else n)
            counts.append(n)
            offset += fixed + n * item
            if offset >= limit:
                break
        return [counts], offset

    def _walk_any(self, offset: int, row: int, rows: int, limit: int):
        """:meth:`walk` for any rows: each list's count read with ``struct``."""
        element, view, end = self.element, self.view, len(self.buffer)
        counts: list[list[int]] = [[] for _ in self.count_types]
        for number in range(row, row + rows):
            k = 0
            for p, item_size, counter in self.plan:
                if counter is None:
                    offset += item_size
                    continue
                if offset + counter.size > end:
                    raise _short(element, end - self.start, offset + counter.size - self.start)
                (n,) = counter.unpack_from(view, offset)
                if not 0 <= n <= element.max_items:
                    raise self._too_many(number, p, n)
                counts[k].append(n)
                k += 1
                offset += counter.size + n * item_size
            if offset >= limit:
                break
        return counts, offset

    def _too_many(self, row: int, p: Property, n: int) -> MeshFormatError:
        return MeshFormatError(
            f"PLY {self.element.name} row {row} lists {n} items in {p.name!r}; 0 to "
            f"{self.element.max_items} are read"
        )


def binary_columns(buffer: np.ndarray, batch: Batch, element: Element, order: str) -> dict:
    """The columns of a batch of binary rows: name -> values; a list's name -> (items, flat,
    in row order; sizes, one a row)."""
    if batch.counts is None:  # rows of one shape: a view of the file
        table = np.frombuffer(
            buffer,
            dtype=_row_dtype(element, order, batch.shape),
            count=batch.rows,
            offset=batch.begin,
        )
        columns, k = {}, 0
        for p in element.properties:
            if p.count_type is None:
                columns[p.name] = table[p.name]
            else:
                items = table[p.name].reshape(batch.rows, -1).ravel()
                columns[p.name] = (items, np.full(batch.rows, batch.shape[k], dtype=np.int64))
                k += 1
        return columns
    sizes = np.stack(batch.counts, axis=1).astype(np.int64)
    starts = batch.begin + _row_starts(element, sizes)
    columns = {
        p.name: np.empty(batch.rows, p.type) for p in element.properties if p.count_type is None
    }
    lists = element.lists
    items = [np.empty(int(sizes[:, k].sum()), p.type) for k, p in enumerate(lists)]
    firsts = [np.cumsum(sizes[:, k]) - sizes[:, k] for k in range(len(lists))]
    if sizes.shape[1] == 1:  # one list: its sizes are the shapes
        shapes, inverse = np.unique(sizes[:, 0], return_inverse=True)
        shapes = shapes[:, None]
    else:
        shapes, inverse = np.unique(sizes, axis=0, return_inverse=True)
    # One numpy pass per row shape of the batch (one or two, for a mesh of polygons).
    for j, shape in enumerate(shapes):
        rows = np.flatnonzero(inverse.ravel() == j)
        dtype = _row_dtype(element, order, shape)
        raw = np.lib.stride_tricks.sliding_window_view(buffer, dtype.itemsize)[starts[rows]]
        table = raw.view(dtype).ravel()
        for name, column in columns.items():
            column[rows] = table[name]
        for k, p in enumerate(lists):
            if shape[k]:
                items[k][firsts[k][rows, None] + np.arange(shape[k])] = table[p.name]
    for k, p in enumerate(lists):
        columns[p.name] = (items[k], sizes[:, k])
    return columns


def _row_starts(element: Element, sizes: np.ndarray) -> np.ndarray:
    """(rows,) int: where each row begins after the first, whose lists have ``sizes``."""
    row_bytes = np.zeros(len(sizes), dtype=np.int64)
    k = 0
    for p in element.properties:
        row_bytes += np.dtype(p.count_type or p.type).itemsize
        if p.count_type is not None:
            row_bytes += sizes[:, k] * np.dtype(p.type).itemsize
            k += 1
    return np.cumsum(row_bytes) - row_bytes


def _count_offsets(element: Element, shape) -> list[tuple[Property, int]]:
    """(list property, byte offset of its count in a row of list sizes ``shape``)."""
    at, k, out = 0, 0, []
    for p in element.properties:
        if p.count_type is None:
            at += np.dtype(p.type).itemsize
            continue
        out.append((p, at))
        at += np.dtype(p.count_type).itemsize + int(shape[k]) * np.dtype(p.type).itemsize
        k += 1
    return out


def _row_dtype(element: Element, order: str, shape) -> np.dtype:
    """The packed structured dtype of a row whose lists have the sizes ``shape``."""
    fields, k = [], 0
    for p in element.properties:
        if p.count_type is None:
            fields.append((p.name, order + p.type))
        else:
            fields.append((f"{p.name} count", order + p.count_type))
            fields.append((p.name, order + p.type, (int(shape[k]),)))
            k += 1
    return np.dtype(fields)


def _short(element: Element, have: int, need: int) -> MeshFormatError:
    return MeshFormatError(
        f"the PLY {element.name} element ({element.count:,} rows) is cut short: its rows "
        f"need at least {need:,} bytes but {have:,} follow"
    )


# -- ASCII ----------------------------------------------------------------------------------


def ascii_batches(buffer: np.ndarray, position: int, element: Element, chunk_bytes: int):
    """The batches of an element's rows (one a line, about ``chunk_bytes`` a batch) from
    ``position``, and where the element ends."""
    if element.count == 0:
        return [], position
    batches, row, begin = [], 0, position
    for end in chunks(buffer, position, whole_lines=True, chunk_bytes=chunk_bytes):
        chunk = buffer[begin:end]
        lines = count_lines(chunk)
        if row + lines >= element.count:
            take = element.count - row
            end = begin + int(positions(chunk == LF)[take - 1]) + 1
            batches.append(Batch(row, take, begin, end))
            return _checked_size(buffer, batches, element, end - position), end
        if end == len(buffer) and row + lines == element.count - 1 and chunk[-1] != LF:
            batches.append(Batch(row, lines + 1, begin, end))  # the last row ends the file
            return _checked_size(buffer, batches, element, end - position), end
        batches.append(Batch(row, lines, begin, end))
        row, begin = row + lines, end
    raise MeshFormatError(
        f"the PLY {element.name} element declares {element.count:,} rows; the file ends before them"
    )


def _checked_size(buffer, batches: list[Batch], element: Element, size: int) -> list:
    """``batches``, once rows too short for a value of each property (so that making an
    array for them would cost more than the file) are refused."""
    if size < 2 * len(element.properties) * element.count - 1:
        for batch in batches:  # some row lacks a value: reading them says which
            ascii_columns(buffer, batch, element)
    return batches


def ascii_columns(buffer: np.ndarray, batch: Batch, element: Element) -> dict:
    """As :func:`binary_columns`, for ASCII rows."""
    chunk = buffer[batch.begin : batch.end]
    starts = token_starts(chunk)
    values = parse_numbers(chunk, np.float64, len(starts))
    if values is None:
        raise MeshFormatError(f"the PLY {element.name} rows hold a value that is not a number")
    # Values per row: a row is a line.
    if batch.rows == 1:
        per_row = np.array([len(starts)])
    else:
        per_row = np.bincount(np.searchsorted(positions(chunk == LF), starts), minlength=batch.rows)
    row_end = np.cumsum(per_row)
    at = row_end - per_row
    columns: dict = {}
    for p in element.properties:
        _check_values(at, row_end, element, batch.row)
        if p.count_type is None:
            columns[p.name] = values[at]
            at = at + 1
            continue
        sizes = values[at]
        bad = np.flatnonzero((sizes < 0) | (sizes > element.max_items) | (sizes % 1 != 0))
        if bad.size:
            raise MeshFormatError(
                f"PLY {element.name} row {batch.row + int(bad[0])} gives {p.name!r} "
                f"{float(sizes[bad[0]])!r} items; 0 to {element.max_items} are read"
            )
        sizes = sizes.astype(np.int64)
        _check_values(at + sizes, row_end, element, batch.row)
        columns[p.name] = (_spans(values, at + 1, sizes), sizes)  # only indices are checked
        at = at + 1 + sizes
    extra = np.flatnonzero(at != row_end)
    if extra.size:
        raise MeshFormatError(
            f"PLY {element.name} row {batch.row + int(extra[0])} has more values than its "
            "properties"
        )
    return columns


def ascii_sizes(buffer, batch: Batch, element: Element, name: str) -> np.ndarray | None:
    """(rows,) int: the sizes of list ``name`` in ASCII rows, parsed alone when only scalars
    come before it in a row; None otherwise, or when a row is not as it should be (reading
    the rows whole then says how)."""
    before = [p.name for p in element.properties].index(name)
    if any(p.count_type is not None for p in element.properties[:before]):
        return None
    lines = Lines.of(buffer[batch.begin : batch.end], 0)
    if len(lines) != batch.rows or np.any(lines.numbers < before):
        return None
    at = lines.key + before
    sizes = _digits(lines.chunk, lines.tokens.starts[at], lines.tokens.ends[at])
    if sizes is None or np.any(sizes > element.max_items):
        return None
    return sizes


def _digits(chunk: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | None:
    """(tokens,) int: the tokens ``[starts, ends)`` read as numbers of 1 to 3 digits, or
    None when one is not (a sum of digits, faster than parsing text)."""
    lengths = ends - starts
    if np.any((lengths < 1) | (lengths > 3)):
        return None
    values = np.zeros(len(starts), dtype=np.int64)
    for k in range(3):
        longer = lengths > k
        digit = chunk[np.where(longer, starts + k, 0)].astype(np.int64) - ord("0")
        if np.any(longer & ((digit < 0) | (digit > 9))):
            return None
        values = np.where(longer, 10 * values + digit, values)
    return values


def _spans(values: np.ndarray, starts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """``values[starts[r]:starts[r] + sizes[r]]`` for every row ``r``, concatenated (one
    row's: a view)."""
    if len(starts) == 1:
        return values[int(starts[0]) : int(starts[0] + sizes[0])]
    inside = np.zeros(len(values) + 1, dtype=np.int8)
    inside[starts] += 1  # the rows' spans are disjoint and ascending
    inside[starts + sizes] -= 1
    np.cumsum(inside, dtype=np.int8, out=inside)
    return values[inside[:-1].view(bool)]


def _check_values(at: np.ndarray, row_end: np.ndarray, element: Element, row: int) -> None:
    short = np.flatnonzero(at >= row_end)
    if short.size:
        raise MeshFormatError(
            f"PLY {element.name} row {row + int(short[0])} has too few values for its properties"
        )
