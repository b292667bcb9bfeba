"""A local server for the benchmarks that run one (service_bench, soak): a free port on
127.0.0.1 and the wait for its readiness."""

from __future__ import annotations

import socket
import time

import httpx


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_ready(client: httpx.Client, seconds: float = 60) -> None:
    """Until ``/readyz`` answers 200 (the start-up self-check passed)."""
    deadline = time.monotonic() + seconds
    while True:
        try:
            if client.get("/readyz").status_code == 200:
                return
        except httpx.TransportError:
            pass
        if time.monotonic() > deadline:
            raise SystemExit(f"the server did not become ready within {seconds:.0f} s")
        time.sleep(0.2)
