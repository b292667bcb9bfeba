"""OBJ's lines read a chunk at a time: each line's kind from its keyword, the numbers of
``v`` and ``vt`` lines, and the vertex and texture references of ``f`` lines (``v``,
``v/vt``, ``v//vn``, ``v/vt/vn``, negative ones counted back), resolved to 0-based ids and
checked. :mod:`.obj` walks the file with them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import MeshFormatError
from .text import (
    Lines,
    Tokens,
    blank_spans,
    numbers_text,
    parse_numbers,
    parse_spans,
    positions,
    spans_text,
)

_SLASH = 47  # b"/"

#: The kinds of line, by keyword: v, f, vt, g, o, usemtl (0: any other).
OTHER, VERTEX, FACE, TEXCOORD, GROUP, OBJECT, MATERIAL = range(7)


XYZ = "numbers; a vertex needs x, y and z"
CORNERS = "corners; a face needs at least 3"


#: The kind of a line by its keyword's one letter (0: not one of these).
_LETTERS = np.zeros(256, dtype=np.int8)
_LETTERS[[ord("v"), ord("f"), ord("g"), ord("o")]] = VERTEX, FACE, GROUP, OBJECT


def line_kinds(lines: Lines) -> np.ndarray:
    """(lines,) int8: the kind of each line from its keyword."""
    tokens, key = lines.tokens, lines.key
    starts = tokens.starts[key]
    kind = _LETTERS[lines.chunk[starts]]
    kind[tokens.ends[key] - starts != 1] = OTHER  # "vt", "vn", "fo", ...
    kind[lines.keyword(b"vt")] = TEXCOORD
    kind[lines.keyword(b"usemtl")] = MATERIAL
    return kind


def kind_of(chunk: np.ndarray, start: int, end: int) -> int:
    """The kind of a line whose keyword is ``chunk[start:end]``."""
    word = bytes(chunk[start : min(end, start + 7)])  # a keyword is short; a token may not be
    kinds = {b"v": VERTEX, b"vt": TEXCOORD, b"f": FACE, b"g": GROUP, b"o": OBJECT}
    return {**kinds, b"usemtl": MATERIAL}.get(word, OTHER)


@dataclass(frozen=True)
class Lazy:
    """The 0-based file lines of lines ``at``, each counted when asked."""

    lines: Lines
    at: np.ndarray

    def __getitem__(self, k) -> int:
        return self.lines.line(self.at[int(k)])


def unreadable(what: str, line: int) -> MeshFormatError:
    return MeshFormatError(
        f"unreadable {what} on line {line + 1}: every token after the keyword must be a number"
    )


def refuse_short(counts: np.ndarray, line_of, noun: str, needs: str) -> None:
    """Refuse the first of some lines with fewer than three numbers after the keyword
    (``counts`` each; ``line_of(k)`` is the 0-based line of the ``k``-th)."""
    short = np.flatnonzero(counts < 3)
    if short.size:
        line, count = line_of(int(short[0])) + 1, int(counts[short[0]])
        raise MeshFormatError(f"{noun} on line {line} has {count} {needs}")


def vertex_rows(lines: Lines, at: np.ndarray, colors: np.ndarray | None, rows: slice) -> np.ndarray:
    """(len(at), 3) float: x, y, z of the vertex lines ``at``; the 4th to 6th numbers of
    those with six or more, a colour ``r g b``, go to ``colors[rows]`` (when there is one;
    ``v x y z w`` gives none)."""
    counts = lines.numbers[at]
    refuse_short(counts, lambda k: lines.line(at[k]), "vertex", XYZ)
    values, bad = parse_spans(*numbers_text(lines, at), counts, np.float64)
    if values is None:
        raise unreadable("vertex coordinates", lines.line(at[bad]))
    if np.all(counts == 3):
        return values.reshape(-1, 3)
    offsets = np.cumsum(counts) - counts
    if colors is not None:
        coloured = np.flatnonzero(counts >= 6)
        colors[rows][coloured, :3] = values[offsets[coloured, None] + np.arange(3, 6)]
    return values[offsets[:, None] + np.arange(3)]


def texcoord_rows(lines: Lines, at: np.ndarray) -> np.ndarray:
    """(len(at), 2) float: u and v of the ``vt`` lines ``at`` (v 0 where a line gives u
    alone; a w ignored)."""
    counts = lines.numbers[at]
    if np.any(counts < 1):
        raise unreadable("texture coordinates", lines.line(at[int(np.argmin(counts))]))
    values, bad = parse_spans(*numbers_text(lines, at), counts, np.float64)
    if values is None:
        raise unreadable("texture coordinates", lines.line(at[bad]))
    offsets = np.cumsum(counts) - counts
    uv = np.zeros((len(at), 2))
    uv[:, 0] = values[offsets]
    second = counts >= 2
    uv[second, 1] = values[offsets[second] + 1]
    return uv


def without_tails(text: np.ndarray, origin: int, tokens: Tokens) -> int:
    """Blank out, in ``text`` (the chunk's bytes from ``origin`` on), the ``/vt/vn`` tails of
    the face references among ``tokens``; return the first token that is only a tail (``/2``,
    no vertex number), or -1."""
    slashes = positions(text == _SLASH)
    if not slashes.size:
        return -1
    slashes += origin
    holder = np.searchsorted(tokens.starts, slashes, side="right") - 1
    holder, first = np.unique(holder, return_index=True)  # each token's first slash
    tails = slashes[first]
    blank_spans(text, tails - origin, tokens.ends[holder] - origin)
    empty = np.flatnonzero(tails == tokens.starts[holder])
    return int(holder[empty[0]]) if empty.size else -1


def face_references(
    lines: Lines, at: np.ndarray, texture: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """(corners,) int64: the vertex references of the face lines ``at``, in order; with
    ``texture``, their texture references too (0 where a corner has none)."""
    counts = lines.numbers[at]
    refuse_short(counts, lambda k: lines.line(at[k]), "face", CORNERS)
    text, starts, ends = numbers_text(lines, at)
    origin = int(lines.tokens.starts[lines.key[at[0]] + 1])
    uv_refs = None
    if texture:
        corner_tokens = np.repeat(lines.key[at] + 1 - (np.cumsum(counts) - counts), counts)
        corner_tokens += np.arange(len(corner_tokens))
        uv_refs = texture_references(text, origin, lines.tokens, corner_tokens)
    tail = without_tails(text, origin, lines.tokens)
    if tail >= 0:
        line = np.searchsorted(lines.key, tail, side="right") - 1
        raise unreadable("face references", lines.line(line))
    refs, bad = parse_spans(text, starts, ends, counts, np.int64)
    if refs is None:
        raise unreadable("face references", lines.line(at[bad]))
    return refs, uv_refs


def texture_references(text, origin: int, tokens: Tokens, corners: np.ndarray) -> np.ndarray:
    """(len(corners),) int64: the texture part of each face reference ``v/vt/vn`` among the
    ascending tokens ``corners`` of ``text`` (the chunk's bytes from ``origin`` on),
    ``_NO_TEXTURE`` where a reference has none (``v`` or ``v//vn``)."""
    found = np.full(len(corners), _NO_TEXTURE, dtype=np.int64)
    slashes = positions(text == _SLASH)
    if not slashes.size:
        return found
    slashes += origin
    holder = np.searchsorted(tokens.starts, slashes, side="right") - 1
    holders, first, count = np.unique(holder, return_index=True, return_counts=True)
    begin = slashes[first] + 1
    token_end = tokens.ends[holders]
    end = np.where(count > 1, slashes[np.minimum(first + 1, len(slashes) - 1)], token_end)
    given = np.flatnonzero(end > begin)
    if not given.size:
        return found
    spans = spans_text(text, begin[given] - origin, end[given] - origin)
    values = parse_numbers(spans, np.int64, len(given))
    if values is None:
        raise MeshFormatError("unreadable texture references: a v/vt/vn's vt must be a number")
    found[np.searchsorted(corners, holders[given])] = values
    return found


#: A face corner without a texture reference (``v`` or ``v//vn``), before resolving.
_NO_TEXTURE = np.iinfo(np.int64).min


def resolved_texcoord_ids(refs, corners, defined, n_texcoords: int, lines) -> np.ndarray:
    """As :func:`resolve` (which refuses 0), for texture references: none becomes -1."""
    none = refs == _NO_TEXTURE
    if n_texcoords == 0 and not none.all():
        raise MeshFormatError("a face refers to a texture coordinate, but the file has no vt lines")
    refs[none] = 1
    ids = resolved_ids(refs, corners, defined, n_texcoords, lines, noun="texture coordinate")
    ids[none] = -1
    return ids


def resolved_ids(
    refs, corners, defined, n_vertices: int, lines, noun: str = "vertex"
) -> np.ndarray:
    """(corners.sum(),) int64 0-based vertex ids of 1-based or negative (relative)
    references ``refs``, in place; ``defined`` vertices precede each polygon (``lines``:
    their 0-based lines, for the message)."""
    negative = refs < 0
    before = None
    if negative.any():
        before = np.repeat(defined, corners)
        bad = (refs == 0) | (refs > n_vertices) | (refs < -before)
    else:
        bad = (refs == 0) | (refs > n_vertices)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        line = lines[int(np.searchsorted(np.cumsum(corners), k, side="right"))] + 1
        raise MeshFormatError(
            f"face on line {line} refers to {noun} {int(refs[k])}, but the file has "
            f"{n_vertices} {noun.replace('vertex', 'vertice')}s (references count from 1, or "
            "back from -1)"
        )
    refs -= 1
    if before is not None:
        refs[negative] += before[negative] + 1
    return refs
