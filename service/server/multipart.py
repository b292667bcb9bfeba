"""multipart/form-data, parsed in memory.

Starlette's form parser spools large files to a temporary file on disk; a patient's scan must
never touch the disk, so the (size-limited) body is split here instead, as views into it.

A form is read the way python-multipart (the parser of Starlette, and so of FastAPI) reads
it, or refused with a 400: the parts a gateway, a log or a reviewer's tool sees in a body
are the parts the service computes on. The header parameters (the ``Content-Type``'s
``boundary``, the ``Content-Disposition``'s ``name`` and ``filename``) are read by
:func:`header_parameters` twice:

* by the grammar of RFC 9110 / RFC 2045 (a token, or a quoted string whose backslash escapes
  are undone), each parameter matched whole, so a name is exactly a name: ``xboundary`` is
  not ``boundary``. A regular expression that searched for ``boundary=`` once let
  ``xboundary=EVIL; boundary=REAL`` split the body on ``EVIL`` and read parts hidden where
  every other parser sees one field, or the epilogue;
* by the standard library's ``email.message.Message.get_params``, whose split on ``;`` and
  unquoting python-multipart's ``parse_options_header`` copies, so that what is kept agrees
  with the parser a front end's stack runs. python-multipart itself is no dependency of the
  service: it is the tests' independent peer.

The reading is kept only when both agree. They part where the header is ambiguous: a ``\\``
before a closing quote (the library counts quotes, miscounts it and splits elsewhere), or an
escape of an ordinary character (``\a``, which the library keeps as two characters). The
library is not used alone because it decodes RFC 2231's ``boundary*=`` and ``boundary*0=``
into ``boundary``, where python-multipart ignores them (RFC 7578 section 4.2 forbids that
notation in forms): a parameter in it is refused, and so is a parameter given twice, a
missing boundary and one that is not 1 to 70 of RFC 2046's characters. The body is as
strict: it starts with its first delimiter (no preamble), each delimiter is followed by CRLF
or ``--``, a part's header lines are ``token: value`` without control characters, and its
data starts after the blank line that ends them. ``tests/test_multipart.py`` sends generated
bodies through both parsers and requires the same parts or a 4xx.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from email.message import Message
from typing import NoReturn

from ..problems import Problem

_TOKEN = r"[!#$%&'*+\-.^_`|~0-9A-Za-z]+"
#: qdtext and quoted-pair (RFC 9110 section 5.6.4): no control character but HTAB.
_QUOTED = r'"(?:[^"\\\x00-\x08\x0a-\x1f\x7f]|\\[^\x00-\x08\x0a-\x1f\x7f])*"'
_VALUE = re.compile(rf"[ \t]*({_TOKEN}(?:/{_TOKEN})?)[ \t]*")
_PARAMETER = re.compile(rf";[ \t]*(?:({_TOKEN})[ \t]*=[ \t]*({_TOKEN}|{_QUOTED})[ \t]*)?")
_ESCAPE = re.compile(r"\\(.)", re.DOTALL)
#: RFC 2046 section 5.1.1: 1 to 70 of these, the last not a space.
_BOUNDARY = re.compile(r"[0-9A-Za-z'()+_,\-./:=? ]{0,69}[0-9A-Za-z'()+_,\-./:=?]")
_HEADER_LINE = re.compile(rf"({_TOKEN}):[ \t]*([^\x00-\x08\x0a-\x1f\x7f]*)")


@dataclass(frozen=True)
class Part:
    """One form field: its name, the file name if it is a file, and its bytes."""

    name: str
    filename: str | None
    data: memoryview


def header_parameters(value: str, header: str) -> tuple[str, dict[str, str]]:
    """The value (``multipart/form-data``, ``form-data``; lower case) and parameters
    (names in lower case) of a header of that form, read as the module's docstring says.

    Raises
    ------
    Problem
        400 naming ``header`` when its parameters are malformed, read two ways, in RFC 2231's
        notation, or one is given twice.
    """
    found = _VALUE.match(value)
    kind = found[1].lower() if found else ""
    position = found.end() if found else len(value) + 1
    strict = []
    while position < len(value):
        parameter = _PARAMETER.match(value, position)
        if parameter is None:
            _refuse(header, f"is malformed from character {position + 1} on (RFC 9110 5.6.6)")
        name, text = parameter.groups()
        if name is not None:
            unquoted = _ESCAPE.sub(r"\1", text[1:-1]) if text.startswith('"') else text
            strict.append((name.lower(), unquoted))
        position = parameter.end()
    if position > len(value):
        _refuse(header, "has no value before its parameters")
    extended = [name for name, _ in strict if "*" in name]
    if extended:
        _refuse(header, f"gives {extended[0]}, RFC 2231's notation, which RFC 7578 forbids")
    message = Message()
    message["x"] = value
    library = [(name, text) for name, text in message.get_params(header="x")[1:] if name]
    if library != strict:
        _refuse(header, "reads two ways (a backslash escape parsers undo differently)")
    parameters = dict(strict)
    if len(parameters) < len(strict):
        twice = next(name for k, (name, _) in enumerate(strict) if name in dict(strict[:k]))
        _refuse(header, f"gives {twice} more than once")
    return kind, parameters


def _refuse(header: str, why: str) -> NoReturn:
    raise Problem(400, f"{header}: the header {why}", "malformed-multipart", header)


def parse_form(body: bytes, content_type: str) -> dict[str, Part]:
    """The parts of a multipart/form-data body, by field name.

    Raises
    ------
    Problem
        415 when the body is not multipart/form-data, 400 when it or its Content-Type is
        malformed, 422 when a field name comes twice (naming it).
    """
    media_type = content_type.partition(";")[0].strip()
    if media_type.lower() != "multipart/form-data":
        raise Problem(
            415,
            f"send multipart/form-data with a 'mesh' file and a 'params' JSON field, not "
            f"{media_type or 'an untyped body'}",
            "unsupported-media-type",
        )
    _, parameters = header_parameters(content_type, "Content-Type")
    boundary = parameters.get("boundary")
    if boundary is None:
        raise Problem(400, "the multipart Content-Type has no boundary", "malformed-multipart")
    if not _BOUNDARY.fullmatch(boundary):
        raise Problem(
            400,
            f"the multipart boundary {boundary[:80]!r} is not 1 to 70 of RFC 2046's characters",
            "malformed-multipart",
        )
    return _parts(body, b"--" + boundary.encode("latin-1"))


def _parts(body: bytes, delimiter: bytes) -> dict[str, Part]:
    """The parts between ``delimiter``s, the first at the body's start."""
    if not body.startswith(delimiter):
        raise Problem(
            400, "the body does not start with its multipart boundary", "malformed-multipart"
        )
    view = memoryview(body)
    parts: dict[str, Part] = {}
    position = 0
    while True:
        position += len(delimiter)
        if body[position : position + 2] == b"--":
            return parts  # the closing delimiter
        if body[position : position + 2] != b"\r\n":
            raise Problem(
                400, "a multipart boundary is not followed by CRLF", "malformed-multipart"
            )
        header_end = body.find(b"\r\n\r\n", position)
        if header_end < 0:
            raise Problem(400, "a multipart part is cut short", "malformed-multipart")
        next_delimiter = body.find(b"\r\n" + delimiter, header_end + 4)
        if next_delimiter < 0:
            raise Problem(400, "a multipart part is cut short", "malformed-multipart")
        part = _part(body[position + 2 : header_end], view[header_end + 4 : next_delimiter])
        if part.name in parts:
            # Which one was meant cannot be told: refuse rather than take the first.
            raise Problem(
                422,
                f"{part.name}: the form has more than one '{part.name}' part; send it once",
                "invalid-request",
                part.name,
            )
        parts[part.name] = part
        position = next_delimiter + 2


def _part(block: bytes, data: memoryview) -> Part:
    """A part from its header lines and its data."""
    disposition = None
    for line in block.decode("latin-1").split("\r\n") if block else ():
        header = _HEADER_LINE.fullmatch(line)
        if header is None:
            raise Problem(
                400,
                f"a multipart part's header line is malformed: {line[:80]!r}",
                "malformed-multipart",
            )
        if header[1].lower() == "content-disposition":
            if disposition is not None:
                raise Problem(
                    400,
                    "a multipart part has two Content-Disposition headers",
                    "malformed-multipart",
                )
            disposition = header[2]
    values = {} if disposition is None else header_parameters(disposition, "Content-Disposition")[1]
    name = values.get("name")
    if name is None:
        raise Problem(400, "a multipart part has no name", "malformed-multipart")
    return Part(name=name, filename=values.get("filename"), data=data)
