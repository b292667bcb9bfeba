"""Finding a key that a JSON document gives twice in one object.

pydantic's JSON parser keeps the last value of a repeated key, so ``{"center": [0, 0, 1],
"center": "auto"}`` would quietly mean ``"auto"``; :func:`repeated_key` finds such a key so
that the request can be refused instead. It reads a document pydantic has already parsed
(valid JSON), as a check only.

The bodies of /v1/points can be tens of megabytes of numbers in arrays, where no key can
be, so the check first looks at the document with every digit, sign, exponent, point, comma,
bracket and space deleted (``bytes.translate``, a few milliseconds for 15 MB): what is left
is the objects, their keys and string values, with the keys changed alike, so equal keys
stay equal and a document that repeats no key there repeats none. Only when that finds a
repeat (or the document has escapes, which could spell one key two ways) is the whole
document scanned, exactly, for the key's path.
"""

from __future__ import annotations

import json
import re

#: What the quick look deletes: everything of numbers and arrays, and spaces. Never a quote,
#: brace, colon or backslash, so the objects and their keys keep their shape.
_DELETED = b"0123456789.+-eE,[] \t\r\n"

#: The tokens of a JSON document that a key's place depends on, after anything else
#: (numbers, true, false, null, spaces): a string, an array of numbers at most two deep
#: (whole: the points of /v1/points are one token), or a structural character. Possessive,
#: so that nothing backtracks.
_TOKENS = re.compile(
    rb'[^"{}\[\]:,]*+(?:("(?:[^"\\]++|\\.)*+")'
    rb'|(\[(?:[^\[\]{}"]++|\[[^\[\]{}"]*+\])*+\])'
    rb"|([{}\[\]:,]))",
    re.DOTALL,
)


def repeated_key(document: bytes) -> tuple[str | int, ...] | None:
    """The path of the first key given twice in one object of ``document`` (valid JSON),
    for example ``("rotation", "pole")``, with array positions as ints; None when no key is
    repeated."""
    if b"\\" not in document and _first_repeat(document.translate(None, _DELETED)) is None:
        return None
    return _first_repeat(document)


def _first_repeat(document: bytes) -> tuple[str | int, ...] | None:
    """:func:`repeated_key`, by reading every token."""
    # Per open object a set of its keys, per open array None; and per open container the
    # key or position being read (the path so far).
    keys: list[set[str] | None] = []
    path: list[str | int | None] = []
    string = None
    for token in _TOKENS.finditer(document):  # one token at a time: no list of them all
        text, mark = token.group(1), token.group(3)
        if text:
            string = text
            continue
        if mark == b":" and string is not None and keys and keys[-1] is not None:
            key = _decoded(string)
            if key in keys[-1]:
                return (*path[:-1], key)
            keys[-1].add(key)
            path[-1] = key
        elif mark:
            _structure(mark, keys, path)
        string = None
    return None


def _structure(mark: bytes, keys: list, path: list) -> None:
    """Follow an opening or closing brace or bracket, or a comma (the next position in an
    array)."""
    if mark == b"{":
        keys.append(set())
        path.append(None)
    elif mark == b"[":
        keys.append(None)
        path.append(0)
    elif mark in (b"}", b"]"):
        if keys:
            keys.pop()
            path.pop()
    elif mark == b"," and keys and keys[-1] is None:
        path[-1] += 1


def _decoded(string: bytes) -> str:
    """A JSON string token's text (escapes undone, as the parser undoes them)."""
    if b"\\" in string:
        return json.loads(string)
    return string[1:-1].decode("utf-8", "surrogateescape")
