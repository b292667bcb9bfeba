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
per polygon size in the batch (the header and the rows: :mod:`.plyformat`).

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

from dataclasses import replace

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
from .plyformat import (
    Batch,
    Element,
    ascii_batches,
    ascii_columns,
    ascii_sizes,
    binary_batches,
    binary_columns,
    header,
)
from .text import (
    as_bytes_array,
)

_INDEX_NAMES = ("vertex_indices", "vertex_index")
#: The elements whose rows hold triangles.
_TRIANGLE_ELEMENTS = ("face", "tristrips")
#: Rows one numpy pass reads at most (their temporaries are some tens of bytes a row).
_BATCH_ROWS = 1 << 15
#: Strip items turned into triangles in one numpy pass (some 100 bytes of temporaries each).
_STRIP_ITEMS = 1 << 15


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
    order, elements, body = header(data)
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


def _index_property(element: Element) -> str:
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

    def plan(self, elements: list[Element], body: int) -> list[tuple[Element, list[Batch]]]:
        """Every element's batches of rows, in order; counts the triangles (``sink``)."""
        plan, position = [], body
        for element in elements:
            if self.order:
                batches, position = binary_batches(
                    self.buffer, position, element, self.order, self.chunk_bytes, self.batch_rows
                )
            else:
                batches, position = ascii_batches(self.buffer, position, element, self.chunk_bytes)
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

    def _triangles(self, element: Element, batch: Batch) -> None:
        name = self.indices[element.name]
        if self.sink.out is None and element.name == "face" and not self.order:
            sizes = ascii_sizes(self.buffer, batch, element, name)
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

    def _columns(self, element: Element, batch: Batch, only: str | None = None):
        if self.order:
            columns = binary_columns(self.buffer, batch, element, self.order)
        else:
            columns = ascii_columns(self.buffer, batch, element)
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
