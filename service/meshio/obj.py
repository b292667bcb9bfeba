"""Wavefront OBJ: vertices, polygons (fan-triangulated in order) and group names, read from
bytes with whole-file numpy passes (no loop over vertices or faces).

Rules (the API documentation repeats them):

* vertex ``i`` is the file's ``i``-th ``v`` line (0-based); ``vt``, ``vn`` and other lines
  are ignored, as are the texture and normal parts of ``f`` references (``v/vt/vn``);
* a polygon ``f a b c d ...`` becomes the triangles ``(a, b, c), (a, c, d), ...`` in that
  order, so face ids count triangles in file order;
* negative references count back from the last vertex defined so far (OBJ's rule);
* a face belongs to the names of the ``g`` line (each name), the ``o`` line and the
  ``usemtl`` line in force where it appears.
"""

from __future__ import annotations

import numpy as np

from .mesh import Limits, Mesh, MeshFormatError, check_counts, checked_vertices, fan_triangles
from .text import SPACE, TextLines, is_blank, parse_numbers

_HASH, _SLASH = 35, 47


def read_obj(data: bytes, limits: Limits) -> Mesh:
    """Parse an OBJ file held in memory.

    Raises
    ------
    MeshFormatError
        No vertices or faces, unreadable numbers, references outside the vertex list,
        polygons with fewer than three corners, or counts beyond ``limits``.
    """
    lines = _Lines(data)
    data = lines.data  # comments blanked out
    kind = lines.keywords()
    vertex_lines = np.flatnonzero(kind == _VERTEX)
    face_lines = np.flatnonzero(kind == _FACE)
    if vertex_lines.size == 0:
        raise MeshFormatError("no vertex ('v') lines: is this an OBJ file?")
    if face_lines.size == 0:
        raise MeshFormatError("no face ('f') lines: the file holds no polygons")
    corners = lines.tokens[face_lines] - 1
    check_counts(len(vertex_lines), int(np.maximum(corners - 2, 0).sum()), limits)

    numbers = lines.numbers_only(vertex_lines, face_lines)
    vertices = _read_vertices(numbers, lines, vertex_lines)
    faces = _read_faces(numbers, lines, face_lines, vertex_lines)
    groups = _read_groups(data, lines, kind, face_lines)
    return Mesh(vertices=vertices, faces=faces, groups=groups, format="obj")


_OTHER, _VERTEX, _FACE, _GROUP, _OBJECT, _MATERIAL = range(6)


class _Lines:
    """Line boundaries, first non-blank columns and token counts of an OBJ text.

    Comments (``#`` to the end of the line) are blanked out first, in a copy, so every later
    step can read whole runs of lines as one slice of ``data``.
    """

    def __init__(self, data: bytes) -> None:
        buffer = np.frombuffer(data, dtype=np.uint8)
        lines = TextLines.of(buffer)
        hashes = np.flatnonzero(buffer == _HASH)
        if hashes.size:
            line = np.searchsorted(lines.starts, hashes, side="right") - 1
            first_of_line = np.concatenate(([True], line[1:] != line[:-1]))
            buffer = _blanked(buffer, hashes[first_of_line], lines.ends[line[first_of_line]])
            data = buffer.tobytes()
            lines = TextLines.of(buffer)  # the same lines, fewer tokens
        self.data, self.buffer = data, buffer
        #: (lines,) int: where each line starts, ends, and has its first non-blank byte
        self.starts, self.ends, self.first = lines.starts, lines.ends, lines.first
        #: (lines,) int: whitespace-separated tokens per line, keyword included
        self.tokens = lines.tokens

    def numbers_only(self, vertex_lines: np.ndarray, face_lines: np.ndarray) -> bytes:
        """The text with the ``v`` and ``f`` keywords and the ``/vt/vn`` tails of face
        references blanked out, so runs of those lines parse as plain numbers."""
        buffer = self.buffer.copy()
        keyword_lines = np.concatenate((vertex_lines, face_lines))
        buffer[self.first[keyword_lines]] = SPACE
        slashes = np.flatnonzero(buffer == _SLASH)
        on_face_line = np.zeros(len(self.starts), dtype=bool)
        on_face_line[face_lines] = True
        # Only on face lines: a slash elsewhere (a vertex, a name) is not a reference tail.
        slashes = slashes[on_face_line[np.searchsorted(self.starts, slashes, "right") - 1]]
        if slashes.size:
            blanks = np.append(np.flatnonzero(is_blank(buffer)), len(buffer))
            tail_ends = blanks[np.searchsorted(blanks, slashes)]
            first_of_tail = np.concatenate(([True], tail_ends[1:] != tail_ends[:-1]))
            buffer = _blanked(buffer, slashes[first_of_tail], tail_ends[first_of_tail])
        return buffer.tobytes()

    def keywords(self) -> np.ndarray:
        """(lines,) int: the kind of each line from its first token."""
        buffer, first, ends = self.buffer, self.first, self.ends
        kind = np.full(len(first), _OTHER, dtype=np.int8)

        def char(offset: int) -> np.ndarray:
            at = first + offset
            out = np.zeros(len(first), dtype=np.uint8)
            inside = at < ends
            out[inside] = buffer[at[inside]]
            return out

        c0, c1 = char(0), char(1)
        separated = is_blank(c1) | (c1 == 0)
        kind[(c0 == ord("v")) & separated] = _VERTEX
        kind[(c0 == ord("f")) & separated] = _FACE
        kind[(c0 == ord("g")) & separated] = _GROUP
        kind[(c0 == ord("o")) & separated] = _OBJECT
        word = np.ones(len(first), dtype=bool)
        for offset, letter in enumerate(b"usemtl"):
            word &= char(offset) == letter
        word &= is_blank(char(6)) | (char(6) == 0)
        kind[word] = _MATERIAL
        return kind


def _blanked(buffer: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """A copy of ``buffer`` with the disjoint ranges ``[starts, ends)`` set to spaces."""
    edges = np.zeros(len(buffer) + 1, dtype=np.int8)
    edges[starts] += 1
    edges[ends] -= 1  # the ranges never overlap, so +-1 marks suffice
    blanked = buffer.copy()
    blanked[np.cumsum(edges[:-1], dtype=np.int8) > 0] = SPACE
    return blanked


def _runs(line_ids: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges ``[i, j)`` into ``line_ids`` of consecutive line numbers."""
    breaks = np.flatnonzero(np.diff(line_ids) != 1) + 1
    bounds = np.concatenate(([0], breaks, [len(line_ids)]))
    return list(zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True))


def _numbers(data: bytes, lines: _Lines, line_ids: np.ndarray, dtype, what: str) -> np.ndarray:
    """The numbers after the keyword on each of ``line_ids`` (their token counts minus one),
    concatenated, from ``data`` as :meth:`_Lines.numbers_only` leaves it. Runs of consecutive
    lines are parsed as one block of text."""
    parts = []
    for i, j in _runs(line_ids):
        first, last = line_ids[i], line_ids[j - 1]
        text = data[lines.starts[first] : lines.ends[last]]
        expected = int(lines.tokens[line_ids[i:j]].sum()) - (j - i)  # less the keywords
        values = parse_numbers(text, dtype, expected)
        if values is None:
            raise MeshFormatError(
                f"unreadable {what} between lines {first + 1} and {last + 1}: every token "
                "after the keyword must be a number"
            )
        parts.append(values)
    return np.concatenate(parts)


def _refuse_short(line_ids: np.ndarray, counts: np.ndarray, noun: str, needs: str) -> None:
    """Refuse the first of ``line_ids`` with fewer than three numbers after its keyword."""
    short = np.flatnonzero(counts < 3)
    if short.size:
        line, count = line_ids[short[0]] + 1, counts[short[0]]
        raise MeshFormatError(f"{noun} on line {line} has {count} {needs}")


def _read_vertices(data: bytes, lines: _Lines, vertex_lines: np.ndarray) -> np.ndarray:
    """(n, 3) float: x, y, z of each ``v`` line (a 4th or more numbers are ignored)."""
    per_line = lines.tokens[vertex_lines] - 1
    _refuse_short(vertex_lines, per_line, "vertex", "numbers; a vertex needs x, y and z")
    values = _numbers(data, lines, vertex_lines, np.float64, "vertex coordinates")
    if np.all(per_line == 3):
        vertices = values.reshape(-1, 3)
    else:
        offsets = np.concatenate(([0], np.cumsum(per_line)[:-1]))
        vertices = values[offsets[:, None] + np.arange(3)]
    return checked_vertices(vertices, vertex_lines)


def _read_faces(
    data: bytes, lines: _Lines, face_lines: np.ndarray, vertex_lines: np.ndarray
) -> np.ndarray:
    """(m, 3) int triangles in file order."""
    corners = lines.tokens[face_lines] - 1
    _refuse_short(face_lines, corners, "face", "corners; a face needs at least 3")
    references = _numbers(data, lines, face_lines, np.int64, "face references")
    # Resolve 1-based and negative (relative) references to 0-based vertex ids.
    defined = np.searchsorted(vertex_lines, face_lines)  # vertices before each face line
    line_of_reference = np.repeat(np.arange(len(face_lines)), corners)
    ids = np.where(references > 0, references - 1, references + defined[line_of_reference])
    bad = (references == 0) | (ids < 0) | (ids >= len(vertex_lines))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        line = face_lines[line_of_reference[k]] + 1
        raise MeshFormatError(
            f"face on line {line} refers to vertex {int(references[k])}, but the file has "
            f"{len(vertex_lines)} vertices (references count from 1, or back from -1)"
        )
    return fan_triangles(ids, corners).astype(np.int64)


def _read_groups(
    data: bytes, lines: _Lines, kind: np.ndarray, face_lines: np.ndarray
) -> dict[str, np.ndarray]:
    """Group name -> (k, 2) ranges of face ids, from the g (each name), o and usemtl lines in
    force. Faces come in file order, so a naming line covers one range: the triangles from it
    to the next line of its kind."""
    # Triangles before each line of the file: fan triangulation gives corners - 2 per face.
    triangles_before = np.concatenate(([0], np.cumsum(lines.tokens[face_lines] - 3)))
    ranges: dict[str, list[tuple[int, int]]] = {}
    for code, split_names in ((_GROUP, True), (_OBJECT, False), (_MATERIAL, False)):
        naming = np.flatnonzero(kind == code)
        if naming.size == 0:
            continue
        bounds = triangles_before[np.searchsorted(face_lines, np.append(naming, len(kind)))]
        for j, line in enumerate(naming.tolist()):
            text = data[lines.first[line] : lines.ends[line]].decode("utf-8", "replace")
            words = text.split(None, 1)
            rest = words[1].strip() if len(words) > 1 else ""
            names = rest.split() if split_names else ([rest] if rest else [])
            for name in names:
                ranges.setdefault(name, []).append((int(bounds[j]), int(bounds[j + 1])))
    return {name: np.array(spans, dtype=np.int64).reshape(-1, 2) for name, spans in ranges.items()}
