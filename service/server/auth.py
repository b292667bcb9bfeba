"""API keys: with keys configured, every ``/v1`` route needs one.

A key is sent as ``Authorization: Bearer <key>`` or ``X-API-Key: <key>``. Keys are compared
as SHA-256 digests with :func:`hmac.compare_digest`, against every configured key without
stopping at a match, so the time taken says nothing about how much of a key was right.
Health, readiness, metrics, the demo page and the OpenAPI document stay open.
"""

from __future__ import annotations

import hashlib
import hmac

from starlette.types import ASGIApp, Receive, Scope, Send

from ..problems import Problem, problem_response

PROTECTED_PREFIX = "/v1/"


def _digest(key: str | bytes) -> bytes:
    return hashlib.sha256(key.encode() if isinstance(key, str) else key).digest()


class KeyCheck:
    """Whether a presented key is one of ``keys`` (held as digests only)."""

    def __init__(self, keys: tuple[str, ...]) -> None:
        self._digests = tuple(_digest(key) for key in keys)

    def __bool__(self) -> bool:
        return bool(self._digests)

    def accepts(self, presented: bytes) -> bool:
        digest = _digest(presented)
        matched = False
        for known in self._digests:
            matched |= hmac.compare_digest(digest, known)
        return matched


def presented_keys(headers: list[tuple[bytes, bytes]]) -> list[bytes]:
    """The keys a request carries: ``X-API-Key`` and a Bearer ``Authorization``. The two
    are alternatives (as in the OpenAPI document); a request with both passes if either
    key is valid."""
    keys = []
    for name, value in headers:
        if name == b"x-api-key" and value.strip():
            keys.append(value.strip())
        elif name == b"authorization":
            scheme, _, credentials = value.strip().partition(b" ")
            if scheme.lower() == b"bearer" and credentials.strip():
                keys.append(credentials.strip())
    return keys


class RequireApiKey:
    """ASGI middleware: a 401 problem for a ``/v1`` request without a configured key."""

    def __init__(self, app: ASGIApp, check: KeyCheck) -> None:
        self.app, self.check = app, check

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or not self.check
            or not scope["path"].startswith(PROTECTED_PREFIX)
            or scope["method"] == "OPTIONS"  # a CORS preflight carries no credentials
        ):
            await self.app(scope, receive, send)
            return
        keys = presented_keys(scope["headers"])
        if not any([self.check.accepts(key) for key in keys]):  # a list: every key checked
            why = "the API key is not valid" if keys else "no API key was sent"
            refusal = Problem(
                401,
                f"{why}: send it as 'Authorization: Bearer <key>' or 'X-API-Key: <key>'",
                "unauthorized",
                field="Authorization",
                headers={"WWW-Authenticate": 'Bearer realm="meshflat"'},
            )
            await problem_response(refusal)(scope, receive, send)
            return
        await self.app(scope, receive, send)
