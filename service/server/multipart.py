"""multipart/form-data, parsed in memory.

Starlette's form parser spools large files to a temporary file on disk; a patient's scan must
never touch the disk, so the (size-limited) body is split here instead, as views into it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ..problems import Problem

_DISPOSITION_PARAMETER = re.compile(
    r';\s*([a-zA-Z*]+)="((?:[^"\\]|\\.)*)"'  # name="value" (quoted)
    r"|;\s*([a-zA-Z*]+)=([^;]*)"  # name=value
)


@dataclass(frozen=True)
class Part:
    """One form field: its name, the file name if it is a file, and its bytes."""

    name: str
    filename: str | None
    data: memoryview


def parse_form(body: bytes, content_type: str) -> dict[str, Part]:
    """The parts of a multipart/form-data body, by field name.

    Raises
    ------
    Problem
        415 when the body is not multipart/form-data, 400 when it is malformed, 422 when
        a field name comes twice (naming it).
    """
    media_type, _, parameters = content_type.partition(";")
    if media_type.strip().lower() != "multipart/form-data":
        raise Problem(
            415,
            f"send multipart/form-data with a 'mesh' file and a 'params' JSON field, not "
            f"{media_type.strip() or 'an untyped body'}",
            "unsupported-media-type",
        )
    match = re.search(r'boundary\s*=\s*(?:"([^"]+)"|([^";\s]+))', parameters, re.IGNORECASE)
    if not match:
        raise Problem(400, "the multipart Content-Type has no boundary", "malformed-multipart")
    delimiter = b"--" + (match.group(1) or match.group(2)).encode("latin-1")
    view = memoryview(body)
    parts: dict[str, Part] = {}
    position = body.find(delimiter)
    if position < 0:
        raise Problem(400, "the body holds no multipart boundary", "malformed-multipart")
    while True:
        position += len(delimiter)
        if body[position : position + 2] == b"--":
            return parts  # the closing delimiter
        if body[position : position + 2] != b"\r\n":
            raise Problem(
                400, "a multipart boundary is not followed by CRLF", "malformed-multipart"
            )
        header_end = body.find(b"\r\n\r\n", position + 2)
        next_delimiter = body.find(b"\r\n" + delimiter, position + 2)
        if header_end < 0 or next_delimiter < 0 or header_end > next_delimiter:
            raise Problem(400, "a multipart part is cut short", "malformed-multipart")
        headers = _headers(body[position + 2 : header_end])
        disposition = headers.get("content-disposition", "")
        values = _disposition_parameters(disposition)
        name = values.get("name")
        if name is None:
            raise Problem(400, "a multipart part has no name", "malformed-multipart")
        if name in parts:
            # Which one was meant cannot be told: refuse rather than take the first.
            raise Problem(
                422,
                f"{name}: the form has more than one '{name}' part; send it once",
                "invalid-request",
                name,
            )
        parts[name] = Part(
            name=name,
            filename=values.get("filename"),
            data=view[header_end + 4 : next_delimiter],
        )
        position = next_delimiter + 2


def _headers(block: bytes) -> dict[str, str]:
    headers = {}
    for line in block.decode("latin-1").split("\r\n"):
        key, _, value = line.partition(":")
        headers[key.strip().lower()] = value.strip()
    return headers


def _disposition_parameters(disposition: str) -> dict[str, str]:
    values = {}
    for quoted_key, quoted, key, plain in _DISPOSITION_PARAMETER.findall(disposition):
        values[(quoted_key or key).lower()] = quoted if quoted_key else plain.strip()
    return values
