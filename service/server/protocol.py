"""uvicorn's HTTP/1.1 protocol (h11) with a time limit on request headers and problem+json
answers to malformed framing.

uvicorn closes an idle kept-alive connection after ``timeout_keep_alive`` but puts no limit on
how long a request's headers take: a connection that sends nothing, or a header line now and
then, would stay open for ever. Here a timer starts when a connection opens, and again when
the first byte of a next request arrives on a kept-alive one; the headers must be complete
before it fires (MESHFLAT_HEADER_TIMEOUT), or the connection gets a 408 (if it sent anything)
and is closed. The body's pace is the application's to judge (MESHFLAT_MIN_UPLOAD_RATE,
:func:`service.server.admission.read_body`).

An answer sent before its request's body was read (a refusal, a 401, a 404) ends the
connection, closed the way nginx's ``lingering_close`` does: the answer and a FIN go out,
then what the client still sends is read and dropped, unparsed, until it closes, falls
silent for :data:`LINGER_IDLE` seconds or has been at it for MESHFLAT_LINGERING_CLOSE
seconds. Closed at once, the socket would answer the body's next bytes with a reset, and the
client's kernel would drop the answer unread: a client that writes its whole body before
reading, as most do, would see a broken connection instead of its 503 and its
``Retry-After``.

Behind an ingress or a proxy that already bounds header time and closes lingering
connections itself, both can be switched off: MESHFLAT_HEADER_TIMEOUT=0 sets no header timer,
MESHFLAT_LINGERING_CLOSE=0 closes such a connection at once. The protocol subclasses
uvicorn's h11 protocol, so uvicorn is pinned below its next minor version (pyproject.toml).
"""

from __future__ import annotations

import asyncio
import functools
from http import HTTPStatus

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from ..observability import REJECTIONS
from ..problems import PROBLEM_JSON, Problem, problem_body
from ..settings import Settings


@functools.cache
def _settings() -> Settings:
    """The worker's settings (uvicorn makes the protocol by its name: it takes no argument)."""
    return Settings.from_env()


#: Silence that ends the lingering sooner, seconds.
LINGER_IDLE = 0.5


class _LingeringTransport:
    """The connection's transport, as the protocol and uvicorn's request cycle see it: its
    ``close`` lingers while the request's body is unread."""

    def __init__(self, transport: asyncio.Transport, protocol: Protocol) -> None:
        self._transport, self._protocol = transport, protocol
        self.lingering = False

    def __getattr__(self, name: str):
        return getattr(self._transport, name)

    def is_closing(self) -> bool:
        return self.lingering or self._transport.is_closing()

    def close(self) -> None:
        if self.is_closing():
            return
        lingers = _settings().lingering_close > 0
        if lingers and self._protocol.conn.their_state is h11.SEND_BODY:
            self.lingering = True
            self._protocol._start_lingering()
        else:
            self._transport.close()


class Protocol(H11Protocol):
    """:class:`H11Protocol` with a header time limit and a lingering close; pass it as
    uvicorn's ``http``."""

    _header_timer: asyncio.TimerHandle | None = None
    _linger_end: float | None = None  # the loop's time at which lingering stops, once begun
    _linger_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(_LingeringTransport(transport, self))  # type: ignore[arg-type]
        self._start_header_timer()

    def data_received(self, data: bytes) -> None:
        if self._linger_end is not None:
            self._linger_on()  # the rest of a body nobody will read: dropped
            return
        if self._header_timer is None and self.conn.their_state is h11.IDLE:
            self._start_header_timer()  # the first bytes of a next request
        super().data_received(data)
        if self.conn.their_state is not h11.IDLE:
            self._stop_header_timer()

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_header_timer()
        if self._linger_timer is not None:
            self._linger_timer.cancel()
        super().connection_lost(exc)

    def eof_received(self) -> bool | None:
        if self._linger_end is not None:
            self._close_now()  # the client has finished: lingering is over
            return False
        return super().eof_received()

    def on_response_complete(self) -> None:
        """An answer sent before its request's body was read (a 401, a 404, a refusal) ends
        the connection, with a lingering close: otherwise the rest of the body would be read
        and parsed at whatever pace and length the client likes."""
        if self.conn.their_state is h11.SEND_BODY:
            self.server_state.total_requests += 1  # as uvicorn counts a completed response
            self.transport.close()
            return  # no keep-alive timer, no next request: this connection is ending
        super().on_response_complete()

    def _start_lingering(self) -> None:
        self._stop_header_timer()
        if self.timeout_keep_alive_task is not None:
            self.timeout_keep_alive_task.cancel()
        self._linger_end = self.loop.time() + _settings().lingering_close
        self.flow.resume_reading()  # a paused read would leave the body to reset the socket
        transport = self.transport._transport
        if transport.can_write_eof():
            transport.write_eof()  # the answer, then a FIN: the client reads it whole
        self._linger_on()

    def _linger_on(self) -> None:
        """Another :data:`LINGER_IDLE` seconds of reading and dropping, within the total
        (MESHFLAT_LINGERING_CLOSE)."""
        if self._linger_timer is not None:
            self._linger_timer.cancel()
        when = min(self.loop.time() + LINGER_IDLE, self._linger_end)
        self._linger_timer = self.loop.call_at(when, self._close_now)

    def _close_now(self) -> None:
        self.transport._transport.close()

    def _start_header_timer(self) -> None:
        seconds = _settings().header_timeout
        if seconds > 0:  # 0: no limit here (an ingress in front keeps one)
            self._header_timer = self.loop.call_later(seconds, self._headers_too_slow)

    def _stop_header_timer(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None

    def _headers_too_slow(self) -> None:
        self._header_timer = None
        if self.transport.is_closing() or self.conn.their_state is not h11.IDLE:
            return
        if self.conn.our_state is h11.IDLE:
            seconds = _settings().header_timeout
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
