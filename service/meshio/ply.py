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
* other elements (edges, materials, ...) and properties (colours, normals, confidence) are
  skipped; list counts may be of any integer type.

Every count the header declares is checked against the limits and against the bytes that
follow before anything is allocated for it. Rows of fixed size are read in one numpy pass;
a face element whose polygons differ in size is walked once for its list sizes, then read
with one pass per polygon size.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace

import numpy as np

from .mesh import (
    Limits,
    Mesh,
    MeshFormatError,
    MeshTooLargeError,
    check_counts,
    checked_vertices,
    fan_triangles,
)
from .text import LF, TextLines, parse_numbers

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


def read_ply(data: bytes, limits: Limits) -> Mesh:
    """Parse a PLY file held in memory.

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
    return _read_body(data, body, elements, order, vertex, indices, limits)


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


def _read_body(data, body, elements, order, vertex, indices, limits) -> Mesh:
    """The mesh from the rows after the header (``body`` is where they start)."""
    rows = _binary_rows if order else _ascii_rows
    vertices, pieces = None, []
    position = body
    for element in elements:
        columns, position = rows(data, position, element, order)
        if element is vertex:
            vertices = np.stack([columns[k] for k in "xyz"], axis=1).astype(np.float64)
        elif element.name in indices:
            items, sizes = columns[indices[element.name]]
            if element.name == "tristrips" and items.dtype.kind == "u":
                # An unsigned list writes the -1 that ends a strip as its largest value.
                items = np.where(items == np.iinfo(items.dtype).max, -1, items.astype(np.int64))
            items = _indices(items, sizes, element.name)
            if element.name == "face":
                pieces.append(_fan(items, sizes, vertex.count, limits))
            else:
                pieces.append(_strips(items, sizes, vertex.count))
            check_counts(vertex.count, sum(len(piece) for piece in pieces), limits)
    faces = np.concatenate(pieces) if pieces else np.empty((0, 3), dtype=np.int64)
    if not faces.size:
        raise MeshFormatError("the PLY file holds no triangles")
    return Mesh(vertices=checked_vertices(vertices), faces=faces, format="ply")


def _index_property(element: _Element) -> str:
    """The name of a triangle element's list of vertex ids."""
    index = next((p for p in element.properties if p.name in _INDEX_NAMES), None)
    if index is None or index.count_type is None:
        raise MeshFormatError(
            f"the PLY {element.name} element needs a list property 'vertex_indices'"
        )
    return index.name


def _strips(items: np.ndarray, sizes: np.ndarray, n_vertices: int) -> np.ndarray:
    """(t, 3) int: the triangles of triangle strips, row by row, ``-1`` ending a strip
    (module docstring); triangles that repeat a vertex are left out.

    Parameters
    ----------
    items : (k,) int, the rows' lists, flat, in row order
    sizes : (rows,) int, each row's list length
    n_vertices : int
    """
    bad = np.flatnonzero((items < -1) | (items >= n_vertices))
    if bad.size:
        raise MeshFormatError(
            f"PLY tristrips row {_face_of(int(bad[0]), sizes)} refers to vertex "
            f"{int(items[bad[0]])}, but the file has {n_vertices:,} vertices (ids count from 0; "
            "-1 ends a strip)"
        )
    # Every row ends its strips: a -1 after each row, then one sequence.
    ends = np.cumsum(sizes)
    sequence = np.insert(items, ends, -1)
    n = len(sequence)
    if n < 3:
        return np.empty((0, 3), dtype=np.int64)
    position = np.arange(n)
    last_break = np.maximum.accumulate(np.where(sequence == -1, position, -1))
    step = position - last_break - 1  # the item's place in its strip
    first = np.arange(n - 2)
    whole = (sequence[first] >= 0) & (sequence[first + 1] >= 0) & (sequence[first + 2] >= 0)
    first = first[whole]
    a, b, c = sequence[first], sequence[first + 1], sequence[first + 2]
    odd = step[first] % 2 == 1
    triangles = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)
    proper = (a != b) & (b != c) & (a != c)
    return triangles[proper]


def _face_of(item: int, corners: np.ndarray) -> int:
    """The face (row) that flat list item ``item`` belongs to."""
    return int(np.searchsorted(np.cumsum(corners), item, side="right"))


def _indices(items: np.ndarray, corners: np.ndarray, element: str = "face") -> np.ndarray:
    """Vertex references as int64; a float list must hold whole numbers."""
    if items.dtype.kind == "f":
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(~(np.isfinite(items) & (items % 1 == 0) & (np.abs(items) < 2**62)))
        if bad.size:
            row = "face" if element == "face" else f"{element} row"
            raise MeshFormatError(
                f"PLY {row} {_face_of(int(bad[0]), corners)} lists {float(items[bad[0]])!r}, "
                "not a vertex index"
            )
    return items.astype(np.int64)


def _header(data: bytes) -> tuple[str | None, list[_Element], int]:
    """The byte order (None for ASCII), the elements, and where the body starts."""
    lines, body = _header_lines(data)
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


def _header_lines(data: bytes) -> tuple[list[str], int]:
    """The header's lines before ``end_header``, and where the body starts."""
    if not data.startswith(b"ply"):
        raise MeshFormatError("not a PLY file: it does not start with 'ply'")
    head = data[: 1 << 16]
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


def _binary_rows(data: bytes, position: int, element: _Element, order: str):
    """Columns of an element's rows from ``position`` (name -> values; a list's name ->
    (items, flat, in row order; sizes, one a row)), and where the element ends."""
    if element.count == 0:
        return _no_rows(element), position
    if element.fixed:
        dtype = _row_dtype(element, order, ())
        end = position + dtype.itemsize * element.count
        if end > len(data):
            raise _short(element, len(data) - position, end - position)
        table = np.frombuffer(data, dtype=dtype, count=element.count, offset=position)
        return {p.name: table[p.name] for p in element.properties}, end
    smallest = sum(np.dtype(p.count_type or p.type).itemsize for p in element.properties)
    if position + smallest * element.count > len(data):
        raise _short(element, len(data) - position, smallest * element.count)
    shapes, row_bytes = _row_shapes(data, position, element, order)
    starts = position + np.concatenate(([0], np.cumsum(row_bytes)[:-1]))
    end = position + int(row_bytes.sum())
    raw = np.frombuffer(data, dtype=np.uint8)
    lists = [p for p in element.properties if p.count_type is not None]
    columns: dict = {p.name: np.empty(element.count, p.type) for p in element.properties}
    pieces: dict = {p.name: [] for p in lists}
    # One numpy pass per distinct row shape (one, for a mesh of triangles only).
    for shape in np.unique(shapes, axis=0):
        rows = np.flatnonzero((shapes == shape).all(axis=1))
        dtype = _row_dtype(element, order, shape)
        if len(rows) == element.count:
            table = np.frombuffer(data, dtype=dtype, count=element.count, offset=position)
        else:
            table = raw[starts[rows, None] + np.arange(dtype.itemsize)].view(dtype).ravel()
        for p in element.properties:
            if p.count_type is None:
                columns[p.name][rows] = table[p.name]
            else:
                pieces[p.name].append((rows, table[p.name].reshape(len(rows), -1)))
    for k, p in enumerate(lists):
        columns[p.name] = (_in_row_order(pieces[p.name], shapes[:, k], p.type), shapes[:, k])
    return columns, end


def _row_shapes(data: bytes, position: int, element: _Element, order: str):
    """(rows, lists) list sizes and (rows,) byte sizes of an element's rows."""
    (first,), (size,) = _walk_rows(data, position, element, order, 1)
    first = np.array(first, dtype=np.int64)
    count = element.count
    # The usual case, checked in one pass: every row has the first row's shape.
    if position + size * count <= len(data):
        starts = position + size * np.arange(count)
        raw = np.frombuffer(data, dtype=np.uint8)
        same = np.ones(count, dtype=bool)
        for k, (p, at) in enumerate(_count_offsets(element, first)):
            count_dtype = np.dtype(order + p.count_type)
            where = starts[:, None] + at + np.arange(count_dtype.itemsize)
            same &= raw[where].view(count_dtype).ravel() == first[k]
        if same.all():
            return np.tile(first, (count, 1)), np.full(count, size, dtype=np.int64)
    # Polygons of several sizes: walk every row.
    shapes, row_bytes = _walk_rows(data, position, element, order, count)
    return np.array(shapes, dtype=np.int64), np.array(row_bytes, dtype=np.int64)


def _walk_rows(data: bytes, position: int, element: _Element, order: str, rows: int):
    """The list sizes and byte sizes of the first ``rows`` rows from ``position``, reading
    only their counts, with plain ints (a row a few hundred nanoseconds)."""
    plan = [
        (p.name, np.dtype(p.type).itemsize, None)
        if p.count_type is None
        else (p.name, np.dtype(p.type).itemsize, struct.Struct(order + _STRUCT[p.count_type]))
        for p in element.properties
    ]
    shapes: list[list[int]] = []
    row_bytes: list[int] = []
    offset, end = position, len(data)
    for row in range(rows):
        start, shape = offset, []
        for name, item_size, counter in plan:
            if counter is None:
                offset += item_size
                continue
            if offset + counter.size > end:
                raise _short(element, end - position, offset + counter.size - position)
            (n,) = counter.unpack_from(data, offset)
            if not 0 <= n <= element.max_items:
                raise MeshFormatError(
                    f"PLY {element.name} row {row} lists {n} items in {name!r}; 0 to "
                    f"{element.max_items} are read"
                )
            shape.append(n)
            offset += counter.size + n * item_size
        shapes.append(shape)
        row_bytes.append(offset - start)
    if offset > end:
        raise _short(element, end - position, offset - position)
    return shapes, row_bytes


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


def _in_row_order(pieces: list, sizes: np.ndarray, kind: str) -> np.ndarray:
    """Flat list items in row order, from tables read one row shape at a time; ``kind`` is
    the items' type (native byte order: values, not bytes, are copied)."""
    starts = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    items = np.empty(int(sizes.sum()), dtype=kind)
    for rows, table in pieces:
        if table.shape[1]:
            items[starts[rows, None] + np.arange(table.shape[1])] = table
    return items


def _short(element: _Element, have: int, need: int) -> MeshFormatError:
    return MeshFormatError(
        f"the PLY {element.name} element ({element.count:,} rows) is cut short: its rows "
        f"need at least {need:,} bytes but {have:,} follow"
    )


def _no_rows(element: _Element) -> dict:
    return {
        p.name: np.empty(0, p.type)
        if p.count_type is None
        else (np.empty(0, p.type), np.empty(0, np.int64))
        for p in element.properties
    }


# -- ASCII ----------------------------------------------------------------------------------


def _ascii_rows(data: bytes, position: int, element: _Element, _order=None):
    """As :func:`_binary_rows`, for ASCII rows: one row a line."""
    if element.count == 0:
        return _no_rows(element), position
    buffer = np.frombuffer(data, dtype=np.uint8, offset=position)
    newlines = np.flatnonzero(buffer == LF)
    if len(newlines) >= element.count:
        end = int(newlines[element.count - 1]) + 1 if element.count else 0
    elif len(newlines) == element.count - 1 and _last_start(newlines) < len(buffer):
        end = len(buffer)  # the last row has no line feed
    else:
        raise MeshFormatError(
            f"the PLY {element.name} element declares {element.count:,} rows; the file ends "
            "before them"
        )
    block = buffer[:end]
    lines = TextLines.of(block)
    values = parse_numbers(block.tobytes(), np.float64, int(lines.tokens.sum()))
    if values is None:
        raise MeshFormatError(f"the PLY {element.name} rows hold a value that is not a number")
    columns: dict = {}
    row_start = np.concatenate(([0], np.cumsum(lines.tokens)[:-1]))
    row_end = row_start + lines.tokens
    at = row_start.copy()
    for p in element.properties:
        _check_values(at, row_end, element)
        if p.count_type is None:
            columns[p.name] = values[at]
            at = at + 1
            continue
        sizes = values[at]
        bad = np.flatnonzero((sizes < 0) | (sizes > element.max_items) | (sizes % 1 != 0))
        if bad.size:
            raise MeshFormatError(
                f"PLY {element.name} row {int(bad[0])} gives {p.name!r} {float(sizes[bad[0]])!r} "
                f"items; 0 to {element.max_items} are read"
            )
        sizes = sizes.astype(np.int64)
        _check_values(at + sizes, row_end, element)
        offsets = np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)
        items = values[np.repeat(at + 1, sizes) + offsets]
        columns[p.name] = (items, sizes)  # as read: only the face indices are checked
        at = at + 1 + sizes
    extra = np.flatnonzero(at != row_end)
    if extra.size:
        raise MeshFormatError(
            f"PLY {element.name} row {int(extra[0])} has more values than its properties"
        )
    return columns, position + end


def _last_start(newlines: np.ndarray) -> int:
    return int(newlines[-1]) + 1 if len(newlines) else 0


def _check_values(at: np.ndarray, row_end: np.ndarray, element: _Element) -> None:
    short = np.flatnonzero(at >= row_end)
    if short.size:
        raise MeshFormatError(
            f"PLY {element.name} row {int(short[0])} has too few values for its properties"
        )


# -- faces ----------------------------------------------------------------------------------


def _fan(items: np.ndarray, corners: np.ndarray, n_vertices: int, limits: Limits) -> np.ndarray:
    """Fan triangles, in row order, of polygons given as flat ``items`` and ``corners``."""
    short = np.flatnonzero(corners < 3)
    if short.size:
        raise MeshFormatError(
            f"PLY face {int(short[0])} has {int(corners[short[0]])} corners; a face needs 3"
        )
    bad = np.flatnonzero((items < 0) | (items >= n_vertices))
    if bad.size:
        raise MeshFormatError(
            f"PLY face {_face_of(int(bad[0]), corners)} refers to vertex "
            f"{int(items[bad[0]])}, but the file has {n_vertices:,} vertices (ids count from 0)"
        )
    check_counts(n_vertices, int((corners - 2).sum()), limits)
    return fan_triangles(items, corners)
