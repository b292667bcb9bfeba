"""uvicorn's HTTP/1.1 protocol (h11) with a time limit on request headers and problem+json
answers to malformed framing.

uvicorn closes an idle kept-alive connection after ``timeout_keep_alive`` but puts no limit on
how long a request's headers take: a connection that sends nothing, or a header line now and
then, would stay open for ever. Here a timer starts when a connection opens, and again when
the first byte of a next request arrives on a kept-alive one; the headers must be complete
before it fires (MESHFLAT_HEADER_TIMEOUT), or the connection gets a 408 (if it sent anything)
and is closed. The body's pace is the application's to judge (MESHFLAT_MIN_UPLOAD_RATE,
:func:`service.routes.read_body`).
"""

from __future__ import annotations

import asyncio
import functools
from http import HTTPStatus

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from .observability import REJECTIONS
from .problems import PROBLEM_JSON, Problem, problem_body
from .settings import Settings


@functools.cache
def _header_timeout() -> float:
    return Settings.from_env().header_timeout


class Protocol(H11Protocol):
    """:class:`H11Protocol` with a header time limit; pass it as uvicorn's ``http``."""

    _header_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._start_header_timer()

    def data_received(self, data: bytes) -> None:
        if self._header_timer is None and self.conn.their_state is h11.IDLE:
            self._start_header_timer()  # the first bytes of a next request
        super().data_received(data)
        if self.conn.their_state is not h11.IDLE:
            self._stop_header_timer()

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_header_timer()
        super().connection_lost(exc)

    def on_response_complete(self) -> None:
        """An answer sent before its request's body was read (a 401, a 404, a refusal) ends
        the connection: otherwise the rest of the body would be read and thrown away, at
        whatever pace and length the client likes."""
        if self.conn.their_state is h11.SEND_BODY and not self.transport.is_closing():
            self.transport.close()
        super().on_response_complete()

    def _start_header_timer(self) -> None:
        self._header_timer = self.loop.call_later(_header_timeout(), self._headers_too_slow)

    def _stop_header_timer(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None

    def _headers_too_slow(self) -> None:
        self._header_timer = None
        if self.transport.is_closing() or self.conn.their_state is not h11.IDLE:
            return
        if self.conn.our_state is h11.IDLE:
            seconds = _header_timeout()
            problem = Problem(
                408,
                f"the request headers did not arrive within {seconds:g} s "
                "(MESHFLAT_HEADER_TIMEOUT)",
                "time-limit",
            )
            if self.conn.trailing_data[0]:  # part of a request came: say why it ends
                self._send_problem(problem)
                return
        self.transport.close()

    def send_400_response(self, msg: str) -> None:
        """Malformed framing: a problem+json 400 instead of uvicorn's plain text."""
        self._send_problem(
            Problem(400, f"the request is not valid HTTP/1.1: {msg}", "malformed-request")
        )

    def _send_problem(self, problem: Problem) -> None:
        REJECTIONS.labels(problem.kind).inc()
        body = problem_body(problem)
        head = (
            f"HTTP/1.1 {problem.status} {HTTPStatus(problem.status).phrase}\r\n"
            f"content-type: {PROBLEM_JSON}\r\ncontent-length: {len(body)}\r\n"
            "connection: close\r\n\r\n"
        )
        # Written as bytes: the connection's state machine may be in its error state by now.
        self.transport.write(head.encode("ascii") + body)
        self.transport.close()
