"""A request-body size limit enforced while the body streams in.

A declared Content-Length over the limit is refused at once; an undeclared (chunked) body is
counted as it arrives and refused as soon as it passes the limit, before the rest is read.
"""

from __future__ import annotations

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ..problems import Problem, problem_response


class BodyTooLarge(Problem):
    def __init__(self, limit: int) -> None:
        super().__init__(
            413,
            f"the request body exceeds {limit:,} bytes (MESHFLAT_MAX_UPLOAD_BYTES)",
            "body-too-large",
            headers={"Connection": "close"},  # the rest of the body is not read
        )


class BodySizeLimit:
    """ASGI middleware: at most ``limit`` bytes of request body."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        for key, value in scope.get("headers", []):
            if key == b"content-length":
                if not value.isdigit():
                    bad = Problem(400, "Content-Length must be a number of bytes", "bad-length")
                    await problem_response(bad)(scope, receive, send)
                    return
                if int(value) > self.limit:
                    await problem_response(BodyTooLarge(self.limit))(scope, receive, send)
                    return
        received = 0

        async def counted() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.limit:
                    raise BodyTooLarge(self.limit)
            return message

        await self.app(scope, counted, send)
