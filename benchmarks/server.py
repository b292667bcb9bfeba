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
from pathlib import Path

import httpx


def children_of(pid: int) -> list[int]:
    """The process's children (a supervisor's workers), from /proc."""
    return [int(child) for child in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


def status_bytes(key: str, pid: int | str = "self") -> int:
    """An entry of the process's ``/proc/PID/status`` in bytes (VmRSS: resident now, VmHWM:
    its peak); 0 once it has ended."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return 0
    line = next(line for line in status.splitlines() if line.startswith(f"{key}:"))
    return int(line.split()[1]) * 1024


def rss_bytes(pid: int) -> int:
    """The process's resident memory (VmRSS), bytes; 0 once it has ended."""
    return status_bytes("VmRSS", pid)


def cpu_seconds(pid: int) -> float:
    """The process's CPU time so far (user + system), seconds; 0 once it has ended."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return 0.0
    fields = stat.rsplit(")", 1)[1].split()  # after the command name, which may hold spaces
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime


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
