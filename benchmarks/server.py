"""A local server for the benchmarks that run one (service_bench, soak, attack): a free port
on 127.0.0.1, the wait for its readiness, and ``meshflat serve`` run for a block."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

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


@dataclass(frozen=True)
class Served:
    process: subprocess.Popen
    port: int

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"


@contextmanager
def serving(
    settings: dict[str, str], *, own_limits: bool, log=subprocess.DEVNULL
) -> Iterator[Served]:
    """``meshflat serve`` on a free port of 127.0.0.1 with the ``MESHFLAT_*`` ``settings``
    and a temporary TMPDIR, ready when the block starts, stopped by SIGTERM when it ends.
    ``own_limits``: the caller's ``MESHFLAT_*`` variables are left out (the defaults count);
    otherwise they are the server's too. ``log`` takes its stderr (a file: a pipe read only
    at the end would fill and stall the server)."""
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ)
        if own_limits:
            env = {k: v for k, v in env.items() if not k.startswith("MESHFLAT_")}
        env |= settings | {"MESHFLAT_PORT": str(port), "TMPDIR": tmp}
        process = subprocess.Popen(
            [sys.executable, "-m", "service.cli", "serve"],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=log,
        )
        served = Served(process, port)
        try:
            with httpx.Client(base_url=served.url, timeout=5) as client:
                wait_ready(client)
            yield served
        finally:
            process.send_signal(signal.SIGTERM)
            process.wait(90)
