"""Chunks, lines and whitespace-separated tokens of the text formats (OBJ, ASCII PLY, ASCII
STL), found with numpy passes over one chunk of text at a time: no Python loop over lines,
and no per-line or per-token array longer than one chunk's, so a reader's working memory
stays a constant however the file's bytes are spent (blank lines, comments, short tokens).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

SPACE, TAB, CR, LF = 32, 9, 13, 10

#: Bytes of text one numpy pass works on. A chunk ends after a line feed (or, inside a line
#: longer than this, after a blank), and every per-line or per-token array of a pass is at
#: most a chunk's length, so this bounds a reader's working memory whatever the file holds:
#: at worst some 35 bytes a byte of a chunk (lines of one short token, ``g a``), 9 MiB.
#: Larger chunks read no faster. Tests make it small (the readers' ``chunk_bytes``) to put
#: lines on the edges.
CHUNK_BYTES = 1 << 18


def as_bytes_array(data: bytes | memoryview) -> np.ndarray:
    """(len,) uint8 view of ``data`` (no copy)."""
    return np.frombuffer(data, dtype=np.uint8)


def parse_numbers(text: np.ndarray | bytes, dtype, expected: int) -> np.ndarray | None:
    """The whitespace-separated numbers of ``text`` (uint8 array or bytes), or None unless
    every one of its ``expected`` tokens is a number of ``dtype``."""
    if isinstance(text, np.ndarray) and (not len(text) or text[-1] not in _ENDS):
        # numpy reads a last token past the end of an array (bytes end with a NUL): end it.
        text = np.append(text, np.uint8(SPACE))
    try:
        values = np.fromstring(text, dtype=dtype, sep=" ")
    except ValueError:
        return None
    return values if len(values) == expected else None


_ENDS = (SPACE, TAB, CR, LF)


def chunks(
    buffer: np.ndarray,
    start: int = 0,
    stop: int | None = None,
    whole_lines: bool = False,
    chunk_bytes: int = CHUNK_BYTES,
) -> Iterator[int]:
    """The ends of consecutive chunks covering ``buffer[start:stop]``, each about
    ``chunk_bytes`` long (:data:`CHUNK_BYTES`; tests make it small to put lines on the
    edges): a chunk ends just after the last line feed of its window; a window inside a
    longer line ends just after its last blank (space, tab, carriage return), so a line is cut
    between tokens, never inside one, and a window that is one token grows to the next blank.
    With ``whole_lines`` a window inside a line grows to its end."""
    stop = len(buffer) if stop is None else stop
    begin = start
    while begin < stop:
        end = min(begin + chunk_bytes, stop)
        if end < stop:
            end = _cut(buffer, begin, end, stop, whole_lines, chunk_bytes)
        yield end
        begin = end


def _cut(
    buffer: np.ndarray, begin: int, end: int, stop: int, whole_lines: bool, chunk_bytes: int
) -> int:
    """Where a chunk whose window is ``[begin, end)`` ends (see :func:`chunks`)."""
    window = buffer[begin:end]
    for hits in (window == LF,) if whole_lines else (window == LF, blanks(window)):
        last = len(hits) - 1 - int(np.argmax(hits[::-1]))
        if hits[last]:
            return begin + last + 1
    # The window is inside one token (or line): take it whole, up to the next blank (or
    # line feed).
    while end < stop:
        window = buffer[end : min(end + chunk_bytes, stop)]
        hits = window == LF if whole_lines else blanks(window)
        if hits.any():
            return end + int(np.argmax(hits)) + 1
        end += len(window)
    return stop


class ChunkWalk:
    """A pass over a text chunk by chunk (:func:`chunks`): runs of whole lines go to
    :meth:`whole`, a line longer than a chunk goes in pieces cut between tokens to
    :meth:`piece` (``open`` is what its pieces gave so far, None between lines). ``line``
    counts the line feeds before the chunk in hand."""

    line: int = 0
    open: object | None = None

    def walk(self, buffer: np.ndarray, ends) -> None:
        """Every chunk of ``buffer`` (uint8) ending at ``ends``, in order."""
        begin = 0
        for end in ends:
            if self.open is not None:  # the chunk begins with the rest of a long line
                rest = first_line_feed(buffer[begin:end])
                stop = begin + rest if rest >= 0 else end
                self.piece(begin, stop, ends_line=rest >= 0 or end == len(buffer))
                if rest < 0:
                    begin = end
                    continue
                self.line, begin = self.line + 1, stop + 1
            if begin < end and end < len(buffer) and buffer[end - 1] != LF:
                self.piece(begin, end, ends_line=False)  # a line longer than a chunk
            elif begin < end:
                self.whole(begin, end)
                self.line += count_lines(buffer[begin:end])
            begin = end

    def whole(self, begin: int, end: int) -> None:
        """Lines ``[begin, end)`` of the buffer, whole."""
        raise NotImplementedError

    def piece(self, begin: int, end: int, ends_line: bool) -> None:
        """Bytes ``[begin, end)`` of a long line; ``ends_line`` when they end it."""
        raise NotImplementedError


def count_lines(chunk: np.ndarray) -> int:
    """Line feeds in ``chunk``."""
    return int(np.count_nonzero(chunk == LF))


def first_line_feed(chunk: np.ndarray) -> int:
    """The index of the first line feed of ``chunk``, or -1."""
    hits = chunk == LF
    at = int(np.argmax(hits))
    return at if len(hits) and hits[at] else -1


@dataclass(frozen=True)
class Tokens:
    """The whitespace-separated tokens of a chunk of text: token ``j`` spans bytes
    ``[starts[j], ends[j])``; ``first[j]`` when it comes first on its line (the chunk's first
    token counts as first). With a comment mark, a token ends at a mark and the tokens after
    it on its line are left out.

    Attributes
    ----------
    starts, ends : (tokens,) int32
    first : (tokens,) bool
    """

    starts: np.ndarray
    ends: np.ndarray
    first: np.ndarray
    comment: int | None = None  # the comment mark, when the chunk held one

    def __len__(self) -> int:
        return len(self.starts)

    def no_comment_in(self, text: np.ndarray) -> bool:
        """Whether ``text`` (part of the chunk) holds no comment mark."""
        return self.comment is None or not (text == self.comment).any()

    @classmethod
    def of(cls, chunk: np.ndarray, comment: int | None = None) -> Tokens:
        """The tokens of ``chunk`` (uint8, shorter than 2**31 bytes)."""
        filled = ~blanks(chunk)
        marks = None
        if comment is not None:
            marks = chunk == comment
            filled &= ~marks  # a mark ends a token, like a blank
        starts, ends = _edges(filled, rising=True), _edges(filled, rising=False)
        del filled
        tokens = cls(starts, ends, _first_of_lines(chunk, starts, ends))
        if marks is not None and len(starts) and marks.any():
            tokens = tokens._before(chunk, positions(marks))
            tokens = Tokens(tokens.starts, tokens.ends, tokens.first, comment)
        return tokens

    def _before(self, chunk: np.ndarray, marks: np.ndarray) -> Tokens:
        """These tokens less those after a comment mark on their line (``marks``: the
        marks' ascending positions)."""
        starts, first = self.starts, self.first
        after = np.searchsorted(starts, marks)  # the first token after each mark
        marks, after = marks[after < len(starts)], after[after < len(starts)]
        # A mark comments out the rest of its line unless a line feed follows it before the
        # next token.
        same = ~first[after]
        wide = np.flatnonzero(first[after])
        if wide.size:
            bounds = np.empty(2 * len(wide), dtype=np.int64)
            bounds[0::2], bounds[1::2] = marks[wide], starts[after[wide]]
            same[wide] = ~np.logical_or.reduceat(chunk == LF, bounds)[0::2]
        line_starts = positions(first)
        after = after[same]
        stop = np.append(line_starts, len(starts))[np.searchsorted(line_starts, after, "right")]
        stop, earliest = np.unique(stop, return_index=True)  # a line's first mark counts
        # Drop the tokens [after, stop) of each such line: +1 and -1 marks, summed.
        drop = np.zeros(len(starts) + 1, dtype=np.int8)
        drop[after[earliest]] += 1
        drop[stop] -= 1
        keep = np.cumsum(drop[:-1], dtype=np.int8) == 0
        return Tokens(starts[keep], self.ends[keep], first[keep])

    def line_feeds_before(self, chunk: np.ndarray, token: int) -> int:
        """The line feeds of ``chunk`` before token ``token`` (its 0-based line), counted
        when asked (error messages only)."""
        return count_lines(chunk[: self.starts[token]])


def blanks(chunk: np.ndarray) -> np.ndarray:
    """(len,) bool: where ``chunk`` holds a space, tab, carriage return or line feed."""
    blank = chunk == SPACE
    for byte in (LF, TAB, CR):
        blank |= chunk == byte
    return blank


def _edges(filled: np.ndarray, rising: bool) -> np.ndarray:
    """(tokens,) int32: where runs of ``filled`` bytes start (``rising``) or end."""
    if len(filled) == 0:
        return np.zeros(0, dtype=np.int32)
    edge = np.empty(len(filled) + 1, dtype=bool)
    # A run starts at i when byte i is filled and i - 1 is not; it ends where the reverse.
    before, after = (filled[:-1], filled[1:]) if rising else (filled[1:], filled[:-1])
    np.greater(after, before, out=edge[1:-1])
    edge[0], edge[-1] = (filled[0], False) if rising else (False, filled[-1])
    return positions(edge)


def positions(mask: np.ndarray) -> np.ndarray:
    """(count,) int32: ``np.flatnonzero(mask)`` for a mask shorter than 2**31 (a chunk's)."""
    return np.flatnonzero(mask).astype(np.int32)


def _first_of_lines(chunk: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(tokens,) bool: the tokens with a line feed between them and the token before."""
    first = np.empty(len(starts), dtype=bool)
    if not len(starts):
        return first
    first[0] = True
    after = chunk[starts[1:] - 1]
    np.equal(after, LF, out=first[1:])  # the usual case: the line feed just before
    # Wider gaps ("  v", "1  2") may hold a line feed anywhere: look in each.
    wide = np.flatnonzero((starts[1:] - ends[:-1] > 1) & (after != LF))
    if wide.size:
        bounds = np.empty(2 * len(wide), dtype=np.int64)
        bounds[0::2], bounds[1::2] = ends[wide], starts[wide + 1]
        first[wide + 1] = np.logical_or.reduceat(chunk == LF, bounds)[0::2]
    return first


def spans_text(chunk: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(len(chunk) + 1,) uint8: a copy of ``chunk`` with every byte outside the disjoint
    ascending spans ``[starts, ends)`` made a space, and a space after it, so that the spans
    parse as one text (:func:`parse_numbers`)."""
    inside = np.zeros(len(chunk) + 1, dtype=np.int8)
    inside[starts] += 1  # starts are distinct, and so are ends; an empty span cancels out
    inside[ends] -= 1
    np.cumsum(inside, dtype=np.int8, out=inside)
    text = np.full(len(chunk) + 1, SPACE, dtype=np.uint8)
    np.copyto(text[:-1], chunk, where=inside[:-1].view(bool))
    return text


def blank_spans(text: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> None:
    """Make the disjoint spans ``[starts, ends)`` of ``text`` spaces, in place."""
    inside = np.zeros(len(text) + 1, dtype=np.int8)
    inside[starts] += 1
    inside[ends] -= 1
    np.cumsum(inside, dtype=np.int8, out=inside)
    text[inside[:-1].view(bool)] = SPACE


def token_starts(chunk: np.ndarray) -> np.ndarray:
    """(tokens,) int32: where the whitespace-separated tokens of ``chunk`` begin."""
    return _edges(~blanks(chunk), rising=True)


@dataclass(frozen=True)
class Lines:
    """The lines of a chunk of text that hold a token (blank lines, and comments, left out):
    line ``i`` begins with token ``key[i]``, its keyword, which ``numbers[i]`` more follow;
    the chunk begins on 0-based line ``first_line`` of the file.

    Attributes
    ----------
    key, numbers : (lines,) int32
    """

    chunk: np.ndarray
    tokens: Tokens
    key: np.ndarray
    numbers: np.ndarray
    first_line: int

    @classmethod
    def of(cls, chunk: np.ndarray, first_line: int, comment: int | None = None) -> Lines:
        tokens = Tokens.of(chunk, comment)
        key = positions(tokens.first)
        numbers = np.diff(key, append=np.int32(len(tokens)))
        numbers -= 1
        return cls(chunk, tokens, key, numbers, first_line)

    def __len__(self) -> int:
        return len(self.key)

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays (the chunk's own aside)."""
        tokens = self.tokens
        return tokens.starts.nbytes + tokens.ends.nbytes + tokens.first.nbytes + 2 * self.key.nbytes

    def keyword(self, word: bytes, fold_case: bool = False) -> np.ndarray:
        """(lines,) bool: the lines whose keyword is ``word`` (ASCII letters, in either case
        with ``fold_case``)."""
        starts = self.tokens.starts[self.key]
        mine = np.flatnonzero(self.tokens.ends[self.key] - starts == len(word))
        letters = self.chunk[starts[mine, None] + np.arange(len(word))]
        if fold_case:
            letters = letters | 0x20  # lower case (letters only are compared)
        found = np.zeros(len(self.key), dtype=bool)
        found[mine[(letters == np.frombuffer(word, dtype=np.uint8)).all(axis=1)]] = True
        return found

    def line(self, i: int) -> int:
        """The 0-based file line of line ``i`` (counted when asked: error messages)."""
        return self.first_line + self.tokens.line_feeds_before(self.chunk, int(self.key[i]))

    def spans(self, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the tokens after the keyword of each of lines ``at`` (which have some)
        begin and end."""
        key = self.key[at]
        return self.tokens.starts[key + 1], self.tokens.ends[key + self.numbers[at]]


def numbers_text(lines: Lines, at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tokens after the keywords of lines ``at`` (all with some) as one text: a copy of
    the chunk from their first to their last with every other byte a blank (and a blank
    after it); and where each line's tokens begin and end in it."""
    starts, ends = lines.spans(at)
    origin = int(starts[0])
    whole = lines.chunk[origin : ends[-1]]
    starts, ends = starts - origin, ends - origin
    key = lines.key[at[1:]]
    one_letter = np.all(lines.tokens.ends[key] - lines.tokens.starts[key] == 1)
    if at[-1] - at[0] + 1 == len(at) and one_letter and lines.tokens.no_comment_in(whole):
        # Consecutive lines and no comment: only blanks and the lines' one-letter keywords
        # lie between their numbers.
        text = np.empty(len(whole) + 1, dtype=np.uint8)
        text[:-1], text[-1] = whole, SPACE  # a blank after the last number ends it
        text[lines.tokens.starts[key] - origin] = SPACE
        return text, starts, ends
    return spans_text(whole, starts, ends), starts, ends


def parse_spans(text, starts, ends, counts, dtype) -> tuple[np.ndarray | None, int]:
    """The numbers of ``text`` whose spans ``[starts, ends)`` hold ``counts`` numbers each;
    or None and the index of the first span that does not parse (found by bisection,
    parsing less each step)."""
    values = parse_numbers(text, dtype, int(counts.sum()))
    if values is not None:
        return values, -1
    low, high = 0, len(starts)  # the first bad span is in [low, high)
    while high - low > 1:
        middle = (low + high) // 2
        part = text[starts[low] : ends[middle - 1] + 1]  # a blank follows every span
        if parse_numbers(part, dtype, int(counts[low:middle].sum())) is None:
            high = middle
        else:
            low = middle
    return None, low
