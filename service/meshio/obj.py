"""Wavefront OBJ: vertices, polygons (fan-triangulated in order) and group names, read from
bytes with numpy passes over one chunk of text at a time (no loop over lines, vertices or
faces).

Rules (the API documentation repeats them):

* vertex ``i`` is the file's ``i``-th ``v`` line (0-based); a ``v x y z r g b`` line gives
  the vertex a colour (0 to 1, or 0 to 255 when any number exceeds 1; white where a line
  gives none); ``vt`` lines and the texture part of ``f`` references (``v/vt/vn``) give each
  face corner its texture coordinates (:class:`mesh.Attributes`); ``vn`` and other lines,
  and the normal parts of references, are ignored;
* a polygon ``f a b c d ...`` becomes the triangles ``(a, b, c), (a, c, d), ...`` in that
  order, so face ids count triangles in file order;
* negative references count back from the last vertex defined so far (OBJ's rule);
* a face belongs to the names of the ``g`` line (each name), the ``o`` line and the
  ``usemtl`` line in force where it appears.

Memory. The file is read twice, chunk by chunk (:data:`text.CHUNK_BYTES` of text each): a
first pass counts the ``v`` lines and the triangles the ``f`` lines fan out into and checks
them against the limits before anything is allocated for them; the second parses each chunk
into the arrays made for them, (n, 3) float64 vertices and (m, 3) int64 faces. Besides those
a read needs a constant (one chunk's per-line and per-token arrays, a few MiB) and the
group ranges. A line longer than a chunk is read in pieces cut between tokens, so no line,
however long, costs more than a chunk.

The arrays are 24 bytes a vertex (a ``v`` line takes at least 8 bytes) and 24 bytes a
triangle (int64 ids, as the rest of the service computes with), and a group's ranges 16
bytes for each naming line followed by a face (its name takes at least 2 bytes), so a read
needs at most 8 bytes a byte of the file plus the constant, with two exceptions:

* a polygon's corner past the second is a triangle, and costs as little as 2 bytes
  (``f 1 1 1 1 ...``): a file of long polygons whose corners are written with one digit
  (1 to 9) yields up to 12 bytes of faces a byte. An int64 triangle cannot be held in less,
  so there the read needs the faces, at most 24 bytes times ``MESHFLAT_MAX_FACES`` (120 MB),
  plus the constant, and nothing in between;
* each distinct group name is a Python string and array in ``Mesh.groups``, some 300 bytes
  a name (names with no face share one empty array): a file of short distinct names costs
  up to some 45 bytes a byte.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .mesh import (
    Attributes,
    Limits,
    Mesh,
    MeshFormatError,
    MeshTooLargeError,
    check_counts,
    fan_into,
    out_of_range,
    vertex_error,
)
from .objlines import (
    CORNERS,
    FACE,
    GROUP,
    MATERIAL,
    OBJECT,
    TEXCOORD,
    VERTEX,
    XYZ,
    Lazy,
    face_references,
    kind_of,
    line_kinds,
    refuse_short,
    resolved_ids,
    resolved_texcoord_ids,
    texcoord_rows,
    texture_references,
    unreadable,
    vertex_rows,
    without_tails,
)
from .text import (
    CHUNK_BYTES,
    ChunkWalk,
    Lines,
    Tokens,
    as_bytes_array,
    chunks,
    parse_numbers,
    spans_text,
)

_HASH = 35  # b"#"

#: Distinct names a file may give its groups: each costs a few hundred bytes of dictionary
#: however short it is written, so without a bound a file of names alone could cost over
#: 100 bytes per byte (a scan has a handful; CAD exports a few thousand).
MAX_GROUP_NAMES = 65_536


def read_obj(data: bytes | memoryview, limits: Limits, *, chunk_bytes: int = CHUNK_BYTES) -> Mesh:
    """Parse an OBJ file held in memory, ``chunk_bytes`` of text at a time
    (:data:`text.CHUNK_BYTES`; tests make it small to put lines on the chunks' edges).

    Raises
    ------
    MeshFormatError
        No vertices or faces, unreadable numbers, references outside the vertex list,
        polygons with fewer than three corners, or counts beyond ``limits``.
    """
    buffer = as_bytes_array(data)
    counted = _Pass(buffer, kept={}, chunk_bytes=chunk_bytes).run()
    if counted.vertices == 0:
        raise MeshFormatError("no vertex ('v') lines: is this an OBJ file?")
    if counted.face_lines == 0:
        raise MeshFormatError("no face ('f') lines: the file holds no polygons")
    check_counts(counted.vertices, counted.triangles, limits)
    out = _Output(
        np.empty((counted.vertices, 3), dtype=np.float64),
        np.empty((counted.triangles, 3), dtype=np.int64),
        colors=_no_colours(counted.vertices) if counted.coloured else None,
        uv=np.zeros((counted.texcoords, 2)) if counted.texcoords else None,
        uv_faces=np.empty((counted.triangles, 3), np.int64) if counted.texcoords else None,
    )
    filled = _Pass(buffer, out, kept=counted.kept).run()
    if out.bad_vertices:
        first, line = out.first_bad
        raise vertex_error(first, out.vertices[first], out.bad_vertices, line)
    groups = out.names.ranges(filled.triangles)
    return Mesh(
        vertices=out.vertices,
        faces=out.faces,
        groups=groups,
        format="obj",
        attributes=out.attributes(),
    )


def _no_colours(count: int) -> np.ndarray:
    """(count, 4) float32: RGB not given (NaN), alpha 1."""
    colors = np.full((count, 4), np.nan, dtype=np.float32)
    colors[:, 3] = 1.0
    return colors


@dataclass
class _Output:
    """The arrays the filling pass writes: (n, 3) float vertices, (m, 3) int faces, the
    group names, and the first vertex out of range (id, 0-based line) with their count."""

    vertices: np.ndarray
    faces: np.ndarray
    names: _Names = field(default_factory=lambda: _Names())
    bad_vertices: int = 0
    first_bad: tuple[int, int] = (0, 0)
    colors: np.ndarray | None = None  # (n, 4) float32, when a v line gives r g b
    uv: np.ndarray | None = None  # (k, 2) float, the vt lines' u and v
    uv_faces: np.ndarray | None = None  # (m, 3) int, each corner's vt (-1: none)

    def attributes(self) -> Attributes:
        """The colours (0 to 255 when any exceeds 1, as some writers put them, else 0 to
        1) and texture coordinates read (``v`` turned over: an OBJ's grows up the image)."""
        colors, uv = self.colors, self.uv
        if colors is not None:
            rgb = colors[:, :3]
            given = ~np.isnan(rgb[:, 0])
            if np.max(rgb[given], initial=0.0) > 1.0:
                rgb /= 255.0
            rgb[~given] = 1.0  # a vertex without a colour: white
            np.clip(np.nan_to_num(rgb), 0.0, 1.0, out=rgb)
        if uv is not None:
            uv[:, 1] = 1.0 - uv[:, 1]
        return Attributes(colors=colors, uv=uv, uv_faces=self.uv_faces)

    def check(self, start: int, count: int, line_of) -> None:
        """Note those of the ``count`` vertices from ``start`` that are out of range
        (``line_of(k)``: the 0-based line of the ``k``-th)."""
        bad = np.flatnonzero(out_of_range(self.vertices[start : start + count]))
        if bad.size:
            if not self.bad_vertices:
                self.first_bad = (start + int(bad[0]), line_of(int(bad[0])))
            self.bad_vertices += len(bad)


@dataclass
class _Open:
    """A line that goes on into the next chunk: its 0-based number, its kind (None before
    its first token), whether a comment has begun, and what its pieces gave so far."""

    line: int
    kind: int | None = None
    in_comment: bool = False
    count: int = 0  # numbers (a vertex) or corners (a face) so far
    vertex: int = 0  # a vertex (or vt) line's vertex (or texture coordinate) id
    numbers: list = field(default_factory=list)  # a vertex's first six numbers
    prefix: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    uv_prefix: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    text: tuple[int, int] | None = None  # an o/usemtl name's bytes in the file


#: Bytes of the first chunks' token tables the counting pass keeps for the filling pass (a
#: small file is then cut into tokens once).
_KEPT_BYTES = 4 << 20


class _Pass(ChunkWalk):
    """One pass over the file, chunk by chunk: counting (``out`` None) or filling ``out``.

    The counters say what the file held before the chunk in hand: ``line`` line feeds,
    ``vertices`` v lines, ``triangles`` triangles, ``face_lines`` f lines. ``kept`` holds the
    first chunks' lines (by where they begin) for the next pass, up to :data:`_KEPT_BYTES`.
    """

    def __init__(
        self,
        buffer: np.ndarray,
        out: _Output | None = None,
        kept=None,
        chunk_bytes: int = CHUNK_BYTES,
    ) -> None:
        self.buffer, self.out, self.kept = buffer, out, {} if kept is None else kept
        self.chunk_bytes = chunk_bytes
        self.line = self.vertices = self.triangles = self.face_lines = 0
        self.texcoords = self.coloured = 0  # vt lines, and v lines with a colour
        self.open: _Open | None = None
        self.room = _KEPT_BYTES  # for lines kept

    def run(self) -> _Pass:
        buffer = self.buffer
        ends = self.kept.pop("ends", None)  # the counting pass's chunks, for the filling one
        if ends is None:
            ends = self.kept["ends"] = list(chunks(buffer, chunk_bytes=self.chunk_bytes))
        self.walk(buffer, ends)
        return self

    # -- whole lines ------------------------------------------------------------------------

    def whole(self, begin: int, end: int) -> None:
        """Read the whole lines of ``buffer[begin:end]``."""
        lines, kind = self.kept.pop(begin, (None, None)) if self.out is not None else (None, None)
        if lines is None:
            lines = Lines.of(self.buffer[begin:end], self.line, comment=_HASH)
            kind = line_kinds(lines)
            if self.out is None and lines.nbytes + kind.nbytes <= self.room:
                self.kept[begin] = lines, kind
                self.room -= lines.nbytes + kind.nbytes
        if not len(lines):
            return
        numbers = lines.numbers
        vertex_lines, face_lines = kind == VERTEX, kind == FACE
        triangles = np.maximum(numbers - 2, 0, where=face_lines, out=np.zeros_like(numbers))
        if self.out is not None:
            self._fill_lines(lines, kind, triangles)
        self.vertices += int(np.count_nonzero(vertex_lines))
        self.coloured += int(np.count_nonzero(vertex_lines & (numbers >= 6)))
        self.texcoords += int(np.count_nonzero(kind == TEXCOORD))
        self.face_lines += int(np.count_nonzero(face_lines))
        self.triangles += int(triangles.sum())

    def _fill_lines(self, lines: Lines, kind: np.ndarray, triangles: np.ndarray) -> None:
        out = self.out
        vertex_lines = kind == VERTEX
        if vertex_lines.any():
            at = np.flatnonzero(vertex_lines)
            start = self.vertices
            rows = slice(start, start + len(at))
            out.vertices[rows] = vertex_rows(lines, at, out.colors, rows)
            out.check(start, len(at), lambda k: lines.line(at[k]))
        texcoord_lines = kind == TEXCOORD
        if out.uv is not None and texcoord_lines.any():
            at = np.flatnonzero(texcoord_lines)
            out.uv[self.texcoords : self.texcoords + len(at)] = texcoord_rows(lines, at)
        at = np.flatnonzero(kind == FACE)
        if at.size:
            refs, uv_refs = face_references(lines, at, out.uv is not None)
            corners, where = lines.numbers[at], Lazy(lines, at)
            defined = self.vertices + np.cumsum(vertex_lines)[at]  # vertices before each line
            resolved = resolved_ids(refs, corners, defined, len(out.vertices), where)
            start, count = self.triangles, int(triangles.sum())
            fan_into(out.faces[start : start + count], resolved, corners)
            if uv_refs is not None:
                defined = self.texcoords + np.cumsum(texcoord_lines)[at]
                uv_ids = resolved_texcoord_ids(uv_refs, corners, defined, len(out.uv), where)
                fan_into(out.uv_faces[start : start + count], uv_ids, corners)
        naming = np.flatnonzero(kind >= GROUP)
        if naming.size:
            before = self.triangles + np.cumsum(triangles) - triangles
            for code in (GROUP, OBJECT, MATERIAL):
                at = naming[kind[naming] == code]
                if at.size:
                    starts, ends, on = _names(lines, at, code)
                    out.names.add(code, lines.chunk, before[at], on, starts, ends)

    # -- a piece of a line longer than a chunk --------------------------------------------

    def piece(self, begin: int, end: int, ends_line: bool) -> None:
        """Read ``buffer[begin:end]``, a piece of the line :attr:`open` (a new one when
        None) that holds no line feed; ``ends_line`` when the line ends there."""
        chunk = self.buffer[begin:end]
        state = self.open or _Open(self.line)
        tokens = Tokens.of(chunk, comment=_HASH)
        starts, ends = tokens.starts, tokens.ends
        if state.in_comment:
            starts = ends = starts[:0]
        if state.kind is None and len(starts):
            state.kind = int(kind_of(chunk, starts[0], ends[0]))
            starts, ends = starts[1:], ends[1:]
            self._begin_line(state)
        state.in_comment |= bool((chunk == _HASH).any())
        if state.kind in (VERTEX, TEXCOORD):
            self._vertex_piece(state, chunk, starts, ends)
        elif state.kind == FACE:
            self._face_piece(state, chunk, starts, ends)
        elif state.kind is not None and state.kind >= GROUP and self.out is not None:
            self._name_piece(state, begin, starts, ends)
        if ends_line:
            self._end_line(state)
        self.open = None if ends_line else state

    def _begin_line(self, state: _Open) -> None:
        if state.kind == VERTEX:
            state.vertex, self.vertices = self.vertices, self.vertices + 1
        elif state.kind == TEXCOORD:
            state.vertex, self.texcoords = self.texcoords, self.texcoords + 1
        elif state.kind == FACE:
            self.face_lines += 1
        elif state.kind >= GROUP and self.out is not None:
            self.out.names.add(state.kind, self.buffer, np.array([self.triangles]))

    def _vertex_piece(self, state: _Open, chunk, starts, ends) -> None:
        state.count += len(starts)
        if self.out is None or not len(starts):
            return
        values = parse_numbers(spans_text(chunk, starts, ends), np.float64, len(starts))
        if values is None:
            raise unreadable("vertex coordinates", state.line)
        had = len(state.numbers)
        state.numbers += values[: 6 - had].tolist()
        if state.kind == VERTEX and had < 3 <= len(state.numbers):
            self.out.vertices[state.vertex] = state.numbers[:3]
            self.out.check(state.vertex, 1, lambda _: state.line)

    def _face_piece(self, state: _Open, chunk, starts, ends) -> None:
        corners = min(state.count, 2) + len(starts)  # the carried corners lead the piece
        state.count += len(starts)
        triangles = max(corners - 2, 0)
        if self.out is not None and len(starts):
            origin = int(starts[0])
            text = spans_text(chunk[origin : ends[-1]], starts - origin, ends - origin)
            tokens = Tokens(starts, ends, starts > 0)
            uv_refs = None
            if self.out.uv is not None:
                uv_refs = texture_references(text, origin, tokens, np.arange(len(starts)))
            bad = without_tails(text, origin, tokens)
            refs = None if bad >= 0 else parse_numbers(text, np.int64, len(starts))
            if refs is None:
                raise unreadable("face references", state.line)
            one = np.array([len(refs)])
            ids = resolved_ids(refs, one, self.vertices, len(self.out.vertices), [state.line])
            state.prefix = self._fan(state.prefix, ids, corners, triangles, self.out.faces)
            if uv_refs is not None:
                ids = resolved_texcoord_ids(
                    uv_refs, one, self.texcoords, len(self.out.uv), [state.line]
                )
                state.uv_prefix = self._fan(
                    state.uv_prefix, ids, corners, triangles, self.out.uv_faces
                )
        self.triangles += triangles

    def _fan(self, prefix, ids, corners: int, triangles: int, out: np.ndarray) -> np.ndarray:
        """Write the fan triangles of a polygon's piece (``prefix``: its first and last ids
        so far) into ``out`` from :attr:`triangles`; the new prefix."""
        items = np.concatenate((prefix, ids))
        if triangles:
            start = self.triangles
            fan_into(out[start : start + triangles], items, np.array([corners]))
        return items[[0, -1]] if len(items) >= 2 else items

    def _name_piece(self, state: _Open, begin: int, starts, ends) -> None:
        if not len(starts):
            return
        at = np.int64(begin)
        if state.kind == GROUP:  # each token a name of the line in force
            on = np.full(len(starts), -1)
            self.out.names.add(GROUP, self.buffer, [], on, starts + at, ends + at)
            return
        first = state.text[0] if state.text else int(starts[0] + at)
        state.text = (first, int(ends[-1] + at))  # the name runs on, blanks and all

    def _end_line(self, state: _Open) -> None:
        if self.out is None:
            self.coloured += int(state.kind == VERTEX and state.count >= 6)
            return
        if state.kind == VERTEX:
            refuse_short(np.array([state.count]), lambda _: state.line, "vertex", XYZ)
            if self.out.colors is not None and len(state.numbers) >= 6:
                self.out.colors[state.vertex, :3] = state.numbers[3:6]
        if state.kind == TEXCOORD and self.out.uv is not None:
            numbers = state.numbers + [0.0] * (2 - len(state.numbers))
            self.out.uv[state.vertex] = numbers[:2]
        if state.kind == FACE:
            refuse_short(np.array([state.count]), lambda _: state.line, "face", CORNERS)
        if state.kind in (OBJECT, MATERIAL) and state.text:
            (start, end), on = state.text, np.full(1, -1)
            self.out.names.add(state.kind, self.buffer, [], on, [start], [end])


def _names(lines: Lines, at: np.ndarray, code: int):
    """The name spans ``(starts, ends)`` of the naming lines ``at`` (all of kind ``code``)
    and the index into ``at`` of each one's line."""
    tokens, counts = lines.tokens, lines.numbers[at]
    if code == GROUP:  # each token a name: the tokens after each line's keyword
        on = np.repeat(np.arange(len(at), dtype=np.int32), counts)
        mine = np.repeat(lines.key[at] + 1 - (np.cumsum(counts, dtype=np.int32) - counts), counts)
        mine += np.arange(len(mine), dtype=np.int32)
        return tokens.starts[mine], tokens.ends[mine], on
    # The rest of the line is the one name (blanks inside it kept).
    named = np.flatnonzero(counts > 0)
    starts, ends = lines.spans(at[named])
    return starts, ends, named


class _Names:
    """Group names and the face ranges they cover, gathered chunk by chunk.

    A naming line of each kind (g, o, usemtl) covers the triangles from it to the next line
    of its kind; the last line of each kind stays open (``pending``) until the next one, or
    the end of the file, closes it. Ranges are kept per name as arrays, merged where they
    touch, so many lines naming the same group cost little.
    """

    def __init__(self) -> None:
        #: the raw bytes of each distinct name, after b"g" (a g line's token, which may hold
        #: several names) or b"n" (an o or usemtl line's one name), -> its id
        self.ids: dict[bytes, int] = {}
        self.pieces: dict[int, list[np.ndarray]] = {}  # id -> its ranges, of those with some
        self.pending: dict[int, tuple[int, np.ndarray]] = {}  # kind -> open line's bound, ids

    def add(self, code, text, bounds, on=(), starts=(), ends=()) -> None:
        """New naming lines of kind ``code`` at the triangle counts ``bounds``, and names
        ``text[starts[k]:ends[k]]`` on line ``on[k]`` of them (-1: the line left open),
        a batch of names at a time."""
        on, bounds = np.asarray(on, dtype=np.int64), np.asarray(bounds, dtype=np.int64)
        starts, ends = np.asarray(starts), np.asarray(ends)
        bound, still_open = self.pending.get(code, (0, np.zeros(0, dtype=np.int64)))
        last, stops = len(bounds) - 1, np.append(bounds[1:], -1)
        before, opened = [still_open], [np.zeros(0, dtype=np.int64)]
        for batch in range(0, len(on), _NAME_BATCH):
            part = slice(batch, batch + _NAME_BATCH)
            ids, lines = self._ids(code, text, starts[part], ends[part]), on[part]
            before.append(ids[lines == -1])  # on the line left open: its range ends below
            closed = (lines >= 0) & (lines < last)
            self._cover(ids[closed], bounds[lines[closed]], stops[lines[closed]])
            opened.append(ids[lines == last])
        still_open = np.unique(np.concatenate(before))
        if len(bounds):
            self._cover(still_open, bound, int(bounds[0]))
            bound, still_open = int(bounds[-1]), np.unique(np.concatenate(opened))
        self.pending[code] = (bound, still_open)

    def _cover(self, ids: np.ndarray, starts, stops) -> None:
        """Name ``ids[k]`` covers the triangles ``[starts[k], stops[k])``."""
        starts = np.broadcast_to(np.asarray(starts, dtype=np.int64), ids.shape)
        stops = np.broadcast_to(np.asarray(stops, dtype=np.int64), ids.shape)
        full = starts < stops
        ids, starts, stops = ids[full], starts[full], stops[full]
        if not ids.size:
            return
        order = np.argsort(ids, kind="stable")  # by name, then in file order
        ids, spans = ids[order], np.stack((starts[order], stops[order]), axis=1)
        cuts = np.flatnonzero(ids[1:] != ids[:-1]) + 1
        for name, group in zip(
            ids[np.append(0, cuts)].tolist(), np.split(spans, cuts), strict=True
        ):
            self.pieces.setdefault(name, []).append(_merged(group))

    def _ids(self, code, text, starts, ends) -> np.ndarray:
        """(names,) int: the id of each name ``text[starts[k]:ends[k]]`` (one per distinct
        bytes), found with a numpy pass over the names of each length."""
        ids = np.empty(len(starts), dtype=np.int64)
        lengths = ends - starts
        for length in np.unique(lengths).tolist():
            mine = np.flatnonzero(lengths == length)
            keys, inverse = _distinct(text, starts[mine], length)
            kind = b"g" if code == GROUP else b"n"
            known = [self.ids.setdefault(kind + key, len(self.ids)) for key in keys]
            if len(self.ids) > MAX_GROUP_NAMES:
                raise MeshTooLargeError(
                    f"the file has more than {MAX_GROUP_NAMES:,} distinct group names (g, o "
                    f"and usemtl); the limit is {MAX_GROUP_NAMES:,}"
                )
            ids[mine] = np.asarray(known, dtype=np.int64)[inverse]
        return ids

    def ranges(self, triangles: int) -> dict[str, np.ndarray]:
        """Name -> (k, 2) int ranges of face ids, once the file's ``triangles`` are read."""
        for bound, still_open in self.pending.values():
            self._cover(still_open, bound, triangles)
        by_name: dict[str, list[np.ndarray]] = {}
        for raw, name_id in self.ids.items():
            text = raw[1:].decode("utf-8", "replace")
            names = text.split() if raw[:1] == b"g" else [text.strip()] if text.strip() else []
            for name in names:
                by_name.setdefault(name, []).extend(self.pieces.pop(name_id, ()))
        groups = {}
        for name in list(by_name):  # each name's pieces dropped as its array is made
            spans = by_name.pop(name)
            groups[name] = _merged(np.concatenate(spans)) if spans else _NO_RANGES
        return groups


#: The ranges of a name on lines followed by no face (one array, read-only, shared).
_NO_RANGES = np.zeros((0, 2), dtype=np.int64)
_NO_RANGES.flags.writeable = False


#: Names whose ids one numpy pass finds (its temporaries are some 70 bytes a name).
_NAME_BATCH = 1 << 15


def _distinct(text: np.ndarray, starts: np.ndarray, length: int) -> tuple[list[bytes], np.ndarray]:
    """The distinct byte strings ``text[s:s + length]`` for ``s`` in ``starts`` and the index
    of each one's among them."""
    rows = np.lib.stride_tricks.sliding_window_view(text, length)[starts]
    if length <= 8:  # as integers, which sort faster than raw bytes
        padded = np.zeros((len(rows), 8), dtype=np.uint8)
        padded[:, :length] = rows
        keys, inverse = np.unique(padded.view("<u8").ravel(), return_inverse=True)
        return [key.tobytes()[:length] for key in keys], inverse.ravel()
    keys, inverse = np.unique(rows.view(f"V{length}").ravel(), return_inverse=True)
    return [key.tobytes() for key in keys], inverse.ravel()


def _merged(spans: np.ndarray) -> np.ndarray:
    """(k, 2) int: the union of ranges ``spans`` as ascending disjoint ranges, touching
    ones joined."""
    if len(spans) > 1:
        spans = spans[np.argsort(spans[:, 0], kind="stable")]
        reach = np.maximum.accumulate(spans[:, 1])
        fresh = np.append(True, spans[1:, 0] > reach[:-1])
        starts = spans[fresh, 0]
        stops = reach[np.append(np.flatnonzero(fresh)[1:] - 1, len(spans) - 1)]
        spans = np.stack((starts, stops), axis=1)
    return np.ascontiguousarray(spans, dtype=np.int64).reshape(-1, 2)
