"""PLY (ASCII and binary, either byte order), read from memory in the file's own order.

Rules (the API documentation repeats them):

* vertex ``i`` is the ``i``-th row of the ``vertex`` element (its ``x``, ``y``, ``z``);
* a ``face`` row's ``vertex_indices`` (or ``vertex_index``) polygon ``a b c d ...`` becomes the
  triangles ``(a, b, c), (a, c, d), ...`` in that order, as in OBJ;
* a ``tristrips`` row's ``vertex_indices`` (or ``vertex_index``) list is one or more strips
  separated by ``-1``: strip ``s0 s1 s2 s3 ...`` becomes ``(s0, s1, s2), (s2, s1, s3),
  (s2, s3, s4), ...`` (every other triangle swaps its first two corners, so all keep the
  strip's winding); a triangle that repeats a vertex (a join between strips written without
  ``-1``) is no triangle and is left out;
* the file's faces are the triangles of its ``face`` and ``tristrips`` elements, element by
  element in the order of the header, row by row;
* the vertex element's colour (``red green blue alpha``), texture coordinates (``u v``,
  ``s t``) and first ``MAX_PROPERTIES`` other scalar properties, and the face element's
  scalar properties (each polygon's value on every triangle it fans into; NaN on a strip's
  triangles), are kept (:class:`mesh.Attributes`); other elements (edges, materials, ...)
  and list properties are skipped; list counts may be of any integer type.

Every count the header declares is checked against the limits and against the bytes that
follow before anything is allocated for it. The body is read twice, a batch of rows at a
time (about :data:`text.CHUNK_BYTES` of the file): a first pass finds every element's rows
and counts the triangles of the face and strip elements, which are checked against the
limits; the second writes the vertices and triangles into arrays made for them. Binary rows
of one shape are read with one numpy pass per batch; where polygons differ in size, the rows'
list sizes are walked (a row a tenth of a microsecond) and the rows read with one numpy pass
per polygon size in the batch.

Memory: the arrays, (n, 3) float64 vertices and (m, 3) int64 faces, and a constant (the
temporaries of one batch, a few MiB). An ASCII row is never split, so a row longer than a
chunk (a strip of a million ids) costs some 12 bytes an id more. The arrays are at most 8
bytes a byte of the file except where fewer than 3 bytes make a triangle: lists of 1- or
2-byte items (``list uchar uchar``: a 24-byte triangle from each corner past the second) and
ASCII polygons and strips written with one-digit ids (12 bytes of triangles a byte). An
int64 triangle cannot be held in less, so there a read needs the triangles, at most 24 bytes
times ``MESHFLAT_MAX_FACES`` (120 MB), plus the constant. Kept properties add 8 bytes a row
each (a colour 16, texture coordinates 16): a file of byte-sized columns (``uchar x y z`` and
colours and properties) can take some 10 bytes a byte, which the job's budget, charged by
the vertex and the face (:func:`service.capabilities.context.job_bytes`), holds.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace

import numpy as np

from . import text
from .attributes import kept_properties, vertex_attributes
from .mesh import (
    Limits,
    Mesh,
    MeshFormatError,
    MeshTooLargeError,
    check_counts,
    checked_vertices,
    fan_into,
)
from .text import (
    LF,
    Lines,
    as_bytes_array,
    chunks,
    count_lines,
    parse_numbers,
    positions,
    token_starts,
)

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_INDEX_NAMES = ("vertex_indices", "vertex_index")
_MAX_CORNERS = 255  # a polygon with more is surely a misread list
#: The elements whose rows hold triangles.
_TRIANGLE_ELEMENTS = ("face", "tristrips")
#: Rows one numpy pass reads at most (their temporaries are some tens of bytes a row).
_BATCH_ROWS = 1 << 15
#: Runs of rows of one shape shorter than this are walked with their neighbours.
_MIN_RUN = 16
#: Strip items turned into triangles in one numpy pass (some 100 bytes of temporaries each).
_STRIP_ITEMS = 1 << 15


@dataclass(frozen=True)
class _Property:
    name: str
    type: str  # numpy kind code, e.g. "f4"
    count_type: str | None = None  # set for a list property


@dataclass(frozen=True)
class _Element:
    name: str
    count: int
    properties: tuple[_Property, ...]
    max_items: int = _MAX_CORNERS  # the longest list a row may hold

    @property
    def fixed(self) -> bool:
        return all(p.count_type is None for p in self.properties)

    @property
    def lists(self) -> list[_Property]:
        return [p for p in self.properties if p.count_type is not None]


@dataclass(frozen=True)
class _Batch:
    """Rows ``[row, row + rows)`` of an element, in bytes ``[begin, end)``: binary rows of
    one ``shape`` (their list sizes), binary rows of several (``counts``: each list's sizes,
    one a row), or ASCII rows (neither)."""

    row: int
    rows: int
    begin: int
    end: int
    shape: tuple[int, ...] | None = None
    counts: tuple[np.ndarray, ...] | None = None


def read_ply(
    data: bytes | memoryview,
    limits: Limits,
    *,
    chunk_bytes: int = text.CHUNK_BYTES,
    batch_rows: int = _BATCH_ROWS,
    strip_items: int = _STRIP_ITEMS,
) -> Mesh:
    """Parse a PLY file held in memory, a batch of rows at a time: at most ``batch_rows``
    rows (:data:`_BATCH_ROWS`) in about ``chunk_bytes`` of the file
    (:data:`text.CHUNK_BYTES`), and triangle strips ``strip_items`` items at a time
    (:data:`_STRIP_ITEMS`). Tests make them small to put rows and strips on the batches'
    edges.

    Raises
    ------
    MeshFormatError
        Not a PLY file, a malformed header, rows the bytes do not hold, faces referring to
        missing vertices, or counts beyond ``limits``.
    """
    order, elements, body = _header(data)
    # A strip of n items holds up to n - 2 triangles: its lists may be as long as the limit.
    elements = [
        replace(e, max_items=limits.max_faces + 2) if e.name == "tristrips" else e for e in elements
    ]
    vertex, indices = _what_to_read(elements, limits)
    reader = _Body(
        as_bytes_array(data),
        order,
        vertex,
        indices,
        chunk_bytes=chunk_bytes,
        batch_rows=batch_rows,
        strip_items=strip_items,
    )
    plan = reader.plan(elements, body)
    check_counts(vertex.count, reader.sink.triangles, limits)
    vertices, faces = reader.fill(plan)
    if not faces.size:
        raise MeshFormatError("the PLY file holds no triangles")
    dtypes = {p.name: np.dtype(p.type) for p in vertex.properties}
    attributes = replace(
        vertex_attributes(reader.vertex_values, dtypes, faces), face=reader.face_values
    )
    return Mesh(
        vertices=checked_vertices(vertices), faces=faces, format="ply", attributes=attributes
    )


def _what_to_read(elements: list, limits: Limits) -> tuple:
    """The vertex element and, by name, the list property of each triangle element;
    refuses a file without them or with an element beyond the limits."""
    by_name = {element.name: element for element in elements}
    triangles = [by_name[name] for name in _TRIANGLE_ELEMENTS if name in by_name]
    if "vertex" not in by_name or not triangles:
        present = ", ".join(repr(e.name) for e in elements) or "none"
        raise MeshFormatError(
            "the PLY file needs a 'vertex' and a 'face' or 'tristrips' element; it has "
            f"{present} (no other element holds triangles that meshflat reads)"
        )
    vertex = by_name["vertex"]
    scalars = {p.name for p in vertex.properties if p.count_type is None}
    if not {"x", "y", "z"} <= scalars:
        raise MeshFormatError("the PLY vertex element needs scalar x, y and z properties")
    indices = {element.name: _index_property(element) for element in triangles}
    if "face" in by_name:  # at least one triangle a face (a strip may hold none)
        check_counts(vertex.count, by_name["face"].count, limits)
    largest = max(limits.max_vertices, limits.max_faces)
    for element in elements:
        if element.count > largest:
            raise MeshTooLargeError(
                f"the PLY {element.name} element declares {element.count:,} rows; the limit "
                f"is {largest:,}",
            )
    return vertex, indices


def _index_property(element: _Element) -> str:
    """The name of a triangle element's list of vertex ids."""
    index = next((p for p in element.properties if p.name in _INDEX_NAMES), None)
    if index is None or index.count_type is None:
        raise MeshFormatError(
            f"the PLY {element.name} element needs a list property 'vertex_indices'"
        )
    return index.name


class _Body:
    """The rows after the header: found and counted (:meth:`plan`), then read (:meth:`fill`)."""

    def __init__(
        self,
        buffer: np.ndarray,
        order: str | None,
        vertex,
        indices: dict,
        *,
        chunk_bytes: int,
        batch_rows: int,
        strip_items: int,
    ) -> None:
        self.buffer, self.order, self.vertex, self.indices = buffer, order, vertex, indices
        #: A batch's bytes and rows at most (:func:`read_ply`).
        self.chunk_bytes, self.batch_rows = chunk_bytes, batch_rows
        self.sink = _Sink(vertex.count, None, strip_items)
        #: The vertex element's other scalar properties, and the face element's scalar
        #: properties a triangle, as :meth:`fill` reads them (name -> values).
        self.vertex_values: dict[str, np.ndarray] = {}
        self.face_values: dict[str, np.ndarray] = {}

    def plan(self, elements: list[_Element], body: int) -> list[tuple[_Element, list[_Batch]]]:
        """Every element's batches of rows, in order; counts the triangles (``sink``)."""
        plan, position = [], body
        for element in elements:
            if self.order:
                batches, position = _binary_batches(
                    self.buffer, position, element, self.order, self.chunk_bytes, self.batch_rows
                )
            else:
                batches, position = _ascii_batches(self.buffer, position, element, self.chunk_bytes)
            plan.append((element, batches))
            if element.name in self.indices:
                for batch in batches:
                    self._triangles(element, batch)
        return plan

    def fill(self, plan) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) float vertices and (m, 3) int faces, read batch by batch."""
        vertices = np.empty((self.vertex.count, 3), dtype=np.float64)
        scalars = [p.name for p in self.vertex.properties if p.count_type is None]
        self.vertex_values = {
            name: np.empty(self.vertex.count)
            for name in kept_properties([n for n in scalars if n not in ("x", "y", "z")])
        }
        faces = next((element for element, _ in plan if element.name == "face"), None)
        scalars = [p.name for p in faces.properties if p.count_type is None] if faces else []
        self.face_values = {
            name: np.full(self.sink.triangles, np.nan)  # NaN on strips' triangles
            for name in kept_properties(scalars)
        }
        self.sink = _Sink(
            self.vertex.count,
            np.empty((self.sink.triangles, 3), dtype=np.int64),
            self.sink.strip_items,
        )
        for element, batches in plan:
            needed = element is self.vertex or element.name in self.indices
            if not needed and self.order:
                continue  # binary rows were checked when found; ASCII rows are read
            for batch in batches:
                if element is self.vertex:
                    columns = self._columns(element, batch)
                    rows = slice(batch.row, batch.row + batch.rows)
                    for k, axis in enumerate("xyz"):
                        vertices[rows, k] = columns[axis]
                    for name, values in self.vertex_values.items():
                        values[rows] = columns[name]
                elif needed:
                    self._triangles(element, batch)
                else:
                    self._columns(element, batch)
        return vertices, self.sink.out

    def _triangles(self, element: _Element, batch: _Batch) -> None:
        name = self.indices[element.name]
        if self.sink.out is None and element.name == "face" and not self.order:
            sizes = _ascii_sizes(self.buffer, batch, element, name)
            if sizes is not None:  # counting needs only the polygons' sizes
                self.sink.faces(None, sizes, batch.row)
                return
        filling = self.sink.out is not None and element.name == "face" and self.face_values
        columns = self._columns(element, batch) if filling else None
        items, sizes = columns[name] if filling else self._columns(element, batch, only=name)
        if element.name == "face":
            start = self.sink.triangles
            self.sink.faces(items, sizes, batch.row)
            for key, values in self.face_values.items() if filling else ():
                values[start : self.sink.triangles] = np.repeat(columns[key], sizes - 2)
        else:
            self.sink.strips(items, sizes, batch.row)

    def _columns(self, element: _Element, batch: _Batch, only: str | None = None):
        if self.order:
            columns = _binary_columns(self.buffer, batch, element, self.order)
        else:
            columns = _ascii_columns(self.buffer, batch, element)
        return columns if only is None else columns[only]


class _Sink:
    """Where the triangle elements' rows go: counted (``out`` None) or written to ``out``
    ((m, 3) int), ``triangles`` so far; strips ``strip_items`` items at a time."""

    def __init__(self, n_vertices: int, out: np.ndarray | None, strip_items: int) -> None:
        self.n_vertices, self.out, self.triangles = n_vertices, out, 0
        self.strip_items = strip_items
        self.strip = _Strip()

    def faces(self, items: np.ndarray, corners: np.ndarray, row: int) -> None:
        """Fan triangles of polygons given as flat ``items`` and ``corners`` (rows from
        ``row``)."""
        if self.out is None:
            self.triangles += int(np.maximum(corners - 2, 0).sum())
            return
        short = np.flatnonzero(corners < 3)
        if short.size:
            raise MeshFormatError(
                f"PLY face {row + int(short[0])} has {int(corners[short[0]])} corners; a face "
                "needs 3"
            )
        items = _indices(items, corners, row)
        bad = np.flatnonzero((items < 0) | (items >= self.n_vertices))
        if bad.size:
            raise MeshFormatError(
                f"PLY face {row + _face_of(int(bad[0]), corners)} refers to vertex "
                f"{int(items[bad[0]])}, but the file has {self.n_vertices:,} vertices (ids count "
                "from 0)"
            )
        count = int((corners - 2).sum())
        fan_into(self.out[self.triangles : self.triangles + count], items, corners)
        self.triangles += count

    def strips(self, items: np.ndarray, sizes: np.ndarray, row: int) -> None:
        """Triangles of triangle strips, rows from ``row`` (module docstring): each row ends
        its strips. Read a piece of the items at a time, so a long row costs no more."""
        ends = np.cumsum(sizes)  # where each row's items end
        for start in range(0, len(items), self.strip_items):
            piece = _strip_ids(items[start : start + self.strip_items])
            stop = start + len(piece)
            bad = _not_whole(piece)
            if bad < 0 and self.out is not None:
                outside = np.flatnonzero((piece < -1) | (piece >= self.n_vertices))
                bad = int(outside[0]) if outside.size else -1
            if bad >= 0:
                self._refuse_strip(items[start + bad], row + _face_of(start + bad, sizes))
            breaks = ends[(ends > start) & (ends <= stop)] - start
            triangles = self.strip.triangles(np.insert(piece.astype(np.int64), breaks, -1))
            if self.out is not None:
                self.out[self.triangles : self.triangles + len(triangles)] = triangles
            self.triangles += len(triangles)

    def _refuse_strip(self, item, row: int) -> None:
        if np.asarray(item).dtype.kind == "f" and not float(item).is_integer():
            raise MeshFormatError(
                f"PLY tristrips row {row} lists {float(item)!r}, not a vertex index"
            )
        raise MeshFormatError(
            f"PLY tristrips row {row} refers to vertex {int(_strip_ids(np.array([item]))[0])}, "
            f"but the file has {self.n_vertices:,} vertices (ids count from 0; -1 ends a strip)"
        )


def _strip_ids(items: np.ndarray) -> np.ndarray:
    """Strip items as signed ids: an unsigned list writes the -1 ending a strip as its
    largest value."""
    if items.dtype.kind == "u":
        return np.where(items == np.iinfo(items.dtype).max, -1, items.astype(np.int64))
    return items


class _Strip:
    """Triangles of a strip sequence (ids, ``-1`` between strips) read in pieces: the last
    two items of the previous piece and the first one's place in its strip carry over."""

    def __init__(self) -> None:
        self.carried = np.zeros(0, dtype=np.int64)
        self.step = 0  # the first carried item's place in its strip

    def triangles(self, piece: np.ndarray) -> np.ndarray:
        """(t, 3) int: the triangles that end in ``piece``."""
        sequence = np.concatenate((self.carried, piece))
        n = len(sequence)
        if n < 3:
            self.carried = sequence
            return np.zeros((0, 3), dtype=np.int64)
        position = np.arange(n)
        # The place of each item in its strip: the distance from the last -1 before it.
        last_break = np.maximum.accumulate(np.where(sequence == -1, position, -1 - self.step))
        step = position - last_break - 1
        first = np.arange(n - 2)
        whole = (sequence[:-2] >= 0) & (sequence[1:-1] >= 0) & (sequence[2:] >= 0)
        first = first[whole]
        a, b, c = sequence[first], sequence[first + 1], sequence[first + 2]
        odd = step[first] % 2 == 1
        triangles = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)
        self.carried, self.step = sequence[-2:], int(step[-2])
        return triangles[(a != b) & (b != c) & (a != c)]


def _face_of(item: int, corners: np.ndarray) -> int:
    """The face (row) that flat list item ``item`` belongs to."""
    return int(np.searchsorted(np.cumsum(corners), item, side="right"))


def _not_whole(items: np.ndarray) -> int:
    """The first of float ``items`` that is not a whole number (a vertex index), or -1."""
    if items.dtype.kind != "f":
        return -1
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(~(np.isfinite(items) & (items % 1 == 0) & (np.abs(items) < 2**62)))
    return int(bad[0]) if bad.size else -1


def _indices(items: np.ndarray, corners: np.ndarray, row: int) -> np.ndarray:
    """Face vertex references as int64; a float list must hold whole numbers."""
    bad = _not_whole(items)
    if bad >= 0:
        raise MeshFormatError(
            f"PLY face {row + _face_of(bad, corners)} lists {float(items[bad])!r}, not a "
            "vertex index"
        )
    return items.astype(np.int64)


# -- header ---------------------------------------------------------------------------------


def _header(data: bytes | memoryview) -> tuple[str | None, list[_Element], int]:
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
            elements.append(_Element(words[1], int(words[2]), ()))
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


def _with_property(element: _Element, words: list[str], number: int) -> _Element:
    """``element`` with the property of header line ``number`` added."""
    new = _prop(words)
    if any(p.name == new.name for p in element.properties):
        raise MeshFormatError(
            f"PLY header line {number}: {element.name!r} has a second {new.name!r} property"
        )
    return _Element(element.name, element.count, (*element.properties, new))


def _prop(words: list[str]) -> _Property:
    if len(words) == 3 and words[1] in _TYPES:
        return _Property(words[2], _TYPES[words[1]])
    if len(words) == 5 and words[1] == "list" and words[2] in _TYPES and words[3] in _TYPES:
        if _TYPES[words[2]][0] == "f":
            raise MeshFormatError(f"PLY list {words[4]!r} counts with a float type")
        return _Property(words[4], _TYPES[words[3]], _TYPES[words[2]])
    raise MeshFormatError(f"PLY property line not understood: {' '.join(words)!r}")


# -- binary ---------------------------------------------------------------------------------

_STRUCT = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I"}


def _binary_batches(
    buffer: np.ndarray,
    position: int,
    element: _Element,
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
            _Batch(row, n, begin + row * size, begin + (row + n) * size, shape=())
            for row, n in rows
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
        element: _Element,
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

    def batches(self) -> tuple[list[_Batch], int]:
        element, position, row, out = self.element, self.start, 0, []
        while row < element.count:
            counts, stop = self.walk(position, row, 1, 0)
            shape, size, left = tuple(c[0] for c in counts), stop - position, element.count - row
            run = self.run(
                position, shape, size, max(1, min(self.batch_rows, left, self.chunk_bytes // size))
            )
            if run >= min(_MIN_RUN, left):
                out.append(_Batch(row, run, position, position + run * size, shape=shape))
                row, position = row + run, position + run * size
                continue
            counts, stop = self.walk(position, row, min(self.batch_rows, left), self.chunk_bytes)
            sizes = tuple(
                np.frombuffer(c, dtype=np.uint8) if isinstance(c, bytearray) else np.asarray(c, t)
                for c, t in zip(counts, self.count_types, strict=True)
            )
            out.append(_Batch(row, len(counts[0]), position, stop, counts=sizes))
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

    def _too_many(self, row: int, p: _Property, n: int) -> MeshFormatError:
        return MeshFormatError(
            f"PLY {self.element.name} row {row} lists {n} items in {p.name!r}; 0 to "
            f"{self.element.max_items} are read"
        )


def _binary_columns(buffer: np.ndarray, batch: _Batch, element: _Element, order: str) -> dict:
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


def _row_starts(element: _Element, sizes: np.ndarray) -> np.ndarray:
    """(rows,) int: where each row begins after the first, whose lists have ``sizes``."""
    row_bytes = np.zeros(len(sizes), dtype=np.int64)
    k = 0
    for p in element.properties:
        row_bytes += np.dtype(p.count_type or p.type).itemsize
        if p.count_type is not None:
            row_bytes += sizes[:, k] * np.dtype(p.type).itemsize
            k += 1
    return np.cumsum(row_bytes) - row_bytes


def _count_offsets(element: _Element, shape) -> list[tuple[_Property, int]]:
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


def _row_dtype(element: _Element, order: str, shape) -> np.dtype:
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


def _short(element: _Element, have: int, need: int) -> MeshFormatError:
    return MeshFormatError(
        f"the PLY {element.name} element ({element.count:,} rows) is cut short: its rows "
        f"need at least {need:,} bytes but {have:,} follow"
    )


# -- ASCII ----------------------------------------------------------------------------------


def _ascii_batches(buffer: np.ndarray, position: int, element: _Element, chunk_bytes: int):
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
            batches.append(_Batch(row, take, begin, end))
            return _checked_size(buffer, batches, element, end - position), end
        if end == len(buffer) and row + lines == element.count - 1 and chunk[-1] != LF:
            batches.append(_Batch(row, lines + 1, begin, end))  # the last row ends the file
            return _checked_size(buffer, batches, element, end - position), end
        batches.append(_Batch(row, lines, begin, end))
        row, begin = row + lines, end
    raise MeshFormatError(
        f"the PLY {element.name} element declares {element.count:,} rows; the file ends before them"
    )


def _checked_size(buffer, batches: list[_Batch], element: _Element, size: int) -> list:
    """``batches``, once rows too short for a value of each property (so that making an
    array for them would cost more than the file) are refused."""
    if size < 2 * len(element.properties) * element.count - 1:
        for batch in batches:  # some row lacks a value: reading them says which
            _ascii_columns(buffer, batch, element)
    return batches


def _ascii_columns(buffer: np.ndarray, batch: _Batch, element: _Element) -> dict:
    """As :func:`_binary_columns`, for ASCII rows."""
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


def _ascii_sizes(buffer, batch: _Batch, element: _Element, name: str) -> np.ndarray | None:
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


def _check_values(at: np.ndarray, row_end: np.ndarray, element: _Element, row: int) -> None:
    short = np.flatnonzero(at >= row_end)
    if short.size:
        raise MeshFormatError(
            f"PLY {element.name} row {row + int(short[0])} has too few values for its properties"
        )
