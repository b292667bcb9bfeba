"""STL, binary or ASCII, read with numpy. STL stores every triangle with its own three
corners; they are kept (nothing is merged), so vertex ``3 i + k`` is corner ``k`` of
triangle ``i``.

A file is binary when its length is exactly what its triangle count says (80-byte header,
count, 50 bytes a triangle), and is then read as one table of triangles. Otherwise it must be
ASCII (``solid ...``), read like OBJ a chunk of lines at a time (:data:`text.CHUNK_BYTES`):
a first pass counts the ``vertex`` lines, checked against the limits before anything is
allocated, then a second parses their numbers into the array made for them. A ``vertex``
line holds exactly three numbers, there are three a triangle, and an ``endsolid`` line comes
after the last; other lines (``facet normal``, ``outer loop``, ...) are not read. Keywords
count in either case, as exporters write them.

Memory: the vertices (24 bytes a corner, 72 a triangle) and faces (24 bytes a triangle), at
most 2 bytes a byte of a binary file (50 bytes a triangle) and 4 of an ASCII one (a triangle
takes at least 24 bytes of ``vertex`` lines), plus a constant: the temporaries of one chunk.
A line longer than a chunk is read in pieces cut between tokens.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field

import numpy as np

from .mesh import Limits, Mesh, MeshFormatError, check_counts, checked_vertices
from .text import (
    CHUNK_BYTES,
    ChunkWalk,
    Lines,
    Tokens,
    as_bytes_array,
    chunks,
    numbers_text,
    parse_numbers,
    parse_spans,
    spans_text,
)

#: A binary STL triangle: its normal, its three corners and the attribute word.
_FACET = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


def read_stl(data: bytes | memoryview, limits: Limits, *, chunk_bytes: int = CHUNK_BYTES) -> Mesh:
    """An STL file (module docstring); an ASCII one read ``chunk_bytes`` of text at a time
    (:data:`text.CHUNK_BYTES`; tests make it small to put lines on the chunks' edges).

    Raises
    ------
    MeshFormatError
        Neither a binary STL nor an ASCII one, unreadable or misplaced numbers, no
        triangles, or counts beyond ``limits``.
    """
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if len(data) == 84 + _FACET.itemsize * count:  # binary
            check_counts(3 * count, count, limits)
            return _binary(data, count)
    if not re.match(rb"\s*solid", bytes(data[:1024])):
        raise MeshFormatError(
            "not an STL file: neither a binary STL (80-byte header, count, 50 bytes per "
            "triangle) nor ASCII ('solid ...')"
        )
    buffer = as_bytes_array(data)
    counted = _Pass(buffer, chunk_bytes=chunk_bytes).run()
    corners = counted.vertices
    check_counts(corners, corners // 3, limits)
    if corners == 0:
        raise MeshFormatError("the STL file holds no triangles")
    if corners % 3:
        raise MeshFormatError(
            f"the ASCII STL file has {corners:,} 'vertex' lines, not a multiple of 3 (a facet "
            "has three corners)"
        )
    if counted.ended <= counted.last_vertex:
        raise MeshFormatError(
            "the ASCII STL file has no 'endsolid' line after its last 'vertex' line: is it "
            "cut short?"
        )
    vertices = np.empty((corners, 3), dtype=np.float64)
    _Pass(buffer, vertices, chunk_bytes).run()
    return _mesh(vertices)


def _binary(data: bytes | memoryview, count: int) -> Mesh:
    """The triangles of a binary STL holding ``count`` of them (its length checked)."""
    if count == 0:
        raise MeshFormatError("the STL file holds no triangles")
    table = np.frombuffer(data, dtype=_FACET, count=count, offset=84)
    vertices = np.empty((3 * count, 3), dtype=np.float64)
    vertices.reshape(count, 3, 3)[...] = table["corners"]  # cast as copied: no float32 copy
    return _mesh(vertices)


def _mesh(vertices: np.ndarray) -> Mesh:
    """The mesh of triangles ``(3 i, 3 i + 1, 3 i + 2)`` of ``vertices`` ((3 m, 3) float)."""
    faces = np.arange(len(vertices), dtype=np.int64).reshape(-1, 3)
    return Mesh(vertices=checked_vertices(vertices), faces=faces, format="stl")


class _Pass(ChunkWalk):
    """One pass over an ASCII STL, chunk by chunk: counting (``out`` None) or filling
    ``out`` ((n, 3) float) with the corners. ``line`` line feeds and ``vertices`` vertex
    lines came before the chunk in hand; ``last_vertex`` and ``ended`` are where the last
    vertex and endsolid lines begin (-1: none). A line longer than a chunk is read in pieces
    cut between tokens: ``open`` is what its pieces gave so far."""

    def __init__(
        self, buffer: np.ndarray, out: np.ndarray | None = None, chunk_bytes: int = CHUNK_BYTES
    ) -> None:
        self.buffer, self.out, self.chunk_bytes = buffer, out, chunk_bytes
        self.line = self.vertices = 0
        self.last_vertex = self.ended = -1
        self.open: _Open | None = None

    def run(self) -> _Pass:
        self.walk(self.buffer, chunks(self.buffer, chunk_bytes=self.chunk_bytes))
        return self

    def whole(self, begin: int, end: int) -> None:
        lines = Lines.of(self.buffer[begin:end], self.line)
        if len(lines):
            self._read(lines, begin)

    def _read(self, lines: Lines, begin: int) -> None:
        """Count (or read) the vertex lines of ``lines``, a chunk from ``begin``."""
        at = np.flatnonzero(lines.keyword(b"vertex", fold_case=True))
        ended = np.flatnonzero(lines.keyword(b"endsolid", fold_case=True))
        if ended.size:
            self.ended = begin + int(lines.tokens.starts[lines.key[ended[-1]]])
        if not at.size:
            return
        self.last_vertex = begin + int(lines.tokens.starts[lines.key[at[-1]]])
        if self.out is not None:
            self.out[self.vertices : self.vertices + len(at)] = _corners(lines, at)
        self.vertices += len(at)

    def piece(self, begin: int, end: int, ends_line: bool) -> None:
        """Read ``buffer[begin:end]``, a piece of the line :attr:`open` (a new one when
        None) that holds no line feed; ``ends_line`` when the line ends there."""
        chunk = self.buffer[begin:end]
        state = self.open or _Open(self.line)
        tokens = Tokens.of(chunk)
        starts, ends = tokens.starts, tokens.ends
        if state.keyword is None and len(starts):
            state.keyword = bytes(chunk[starts[0] : min(ends[0], starts[0] + 9)]).lower()
            at = begin + int(starts[0])
            if state.keyword == b"vertex":
                self.vertices, self.last_vertex = self.vertices + 1, at
            elif state.keyword == b"endsolid":
                self.ended = at
            starts, ends = starts[1:], ends[1:]
        if state.keyword == b"vertex":
            state.count += len(starts)
            if self.out is not None and len(starts) and len(state.numbers) < 4:
                state.numbers += self._numbers(chunk, starts[: 4 - len(state.numbers)], ends, state)
        if ends_line and state.keyword == b"vertex" and self.out is not None:
            if state.count != 3:
                raise _wrong_count(state.line, state.count)
            self.out[self.vertices - 1] = state.numbers
        self.open = None if ends_line else state

    def _numbers(self, chunk, starts, ends, state: _Open) -> list[float]:
        values = parse_numbers(
            spans_text(chunk, starts, ends[: len(starts)]), np.float64, len(starts)
        )
        if values is None:
            raise _unreadable(state.line)
        return values.tolist()


@dataclass
class _Open:
    """A line that goes on into the next chunk: its 0-based number, its keyword (lower
    case; None before its first token), and a vertex line's numbers so far."""

    line: int
    keyword: bytes | None = None
    count: int = 0
    numbers: list = field(default_factory=list)


def _wrong_count(line: int, count: int) -> MeshFormatError:
    return MeshFormatError(
        f"'vertex' on line {line + 1} of the STL file has {count} numbers; a corner has x, y and z"
    )


def _unreadable(line: int) -> MeshFormatError:
    return MeshFormatError(f"unreadable 'vertex' numbers on line {line + 1} of the STL file")


def _corners(lines: Lines, at: np.ndarray) -> np.ndarray:
    """(len(at), 3) float: the x, y, z of the vertex lines ``at``."""
    counts = lines.numbers[at]
    wrong = np.flatnonzero(counts != 3)
    if wrong.size:
        raise _wrong_count(lines.line(at[wrong[0]]), int(counts[wrong[0]]))
    values, bad = parse_spans(*numbers_text(lines, at), counts, np.float64)
    if values is None:
        raise _unreadable(lines.line(at[bad]))
    return values.reshape(-1, 3)
