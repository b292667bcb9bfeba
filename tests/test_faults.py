"""Faults against a real ``meshflat serve`` with two workers on 127.0.0.1: a client that
disconnects mid-upload, a job past its time limit, a worker killed mid-request. Each leaves
the service healthy: it answers, and counts no job in flight once the work is gone."""

from __future__ import annotations

import json
import os
import signal
import socket
import threading
import time
from pathlib import Path

import httpx
import pytest

from service.cli import WORKER_SILENCE_S
from service.samples import SAMPLES

from .conftest import real_servers
from .test_operations import families, sample
from .test_serve import HEAD, REGION, SLOW_FIT, running

pytestmark = real_servers


@pytest.fixture
def server(request):
    with running(MESHFLAT_WORKERS="2", **getattr(request, "param", {})) as server:
        yield server


def gauge(client: httpx.Client, name: str) -> float:
    """A gauge of the server, as /metrics says now (summed over its workers)."""
    return sample(families(client.get("/metrics").text), name)


def in_flight(client: httpx.Client) -> float:
    return gauge(client, "meshflat_jobs_in_flight")


def computing(client: httpx.Client) -> float:
    return gauge(client, "meshflat_jobs_computing")


def until(condition, seconds: float = 20) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "not within the time allowed"
        time.sleep(0.05)


def healthy(client: httpx.Client) -> None:
    """Answers, flattens a sample, and has no job left in flight."""
    assert client.get("/healthz").status_code == 200
    data = SAMPLES["fsaverage-head.ply"].path.read_bytes()
    response = client.post(
        "/v1/flatten",
        files={"mesh": ("head.ply", data)},
        data={"params": json.dumps(REGION)},
    )
    assert response.status_code == 200, response.text
    until(lambda: in_flight(client) == 0)


def fit_of_head(client: httpx.Client) -> httpx.Response:
    return client.post(
        "/v1/fit",
        files={"mesh": ("head.ply", HEAD)},
        data={"params": json.dumps(SLOW_FIT)},
    )


def test_a_client_that_disconnects_mid_upload(server):
    with httpx.Client(base_url=server.url, timeout=60) as client:
        for _ in range(4):  # to both workers, most likely
            with socket.create_connection(("127.0.0.1", server.port)) as raw:
                raw.sendall(
                    b"POST /v1/flatten HTTP/1.1\r\nHost: x\r\n"
                    b"Content-Type: multipart/form-data; boundary=b\r\n"
                    b"Content-Length: 1000000\r\n\r\n--b\r\n" + b"v 0 0 0\n" * 1000
                )
                until(lambda: in_flight(client) >= 1)
        healthy(client)
    statuses = [e["status"] for e in server.lines() if e.get("route") == "/v1/flatten"]
    assert 500 not in statuses


@pytest.mark.parametrize("server", [{"MESHFLAT_REQUEST_TIMEOUT": "0.3"}], indirect=True)
def test_a_job_past_its_time_limit(server):
    with httpx.Client(base_url=server.url, timeout=60) as client:
        started = time.monotonic()
        response = fit_of_head(client)
        assert response.status_code == 504, response.text
        assert "0.3 s (MESHFLAT_REQUEST_TIMEOUT)" in response.json()["detail"]
        assert time.monotonic() - started < 5
        until(lambda: in_flight(client) == 0)  # the computation stopped, its slot freed
        assert client.get("/healthz").status_code == 200


def worker_pids(supervisor: int) -> list[int]:
    """The supervisor's worker processes (not multiprocessing's resource tracker, also its
    child)."""
    children = Path(f"/proc/{supervisor}/task/{supervisor}/children").read_text().split()
    workers = []
    for pid in map(int, children):
        try:
            command = Path(f"/proc/{pid}/cmdline").read_bytes()
        except FileNotFoundError:
            continue
        if b"spawn_main" in command:
            workers.append(pid)
    return workers


def cpu_ticks(pid: int) -> int:
    fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    return int(fields[11]) + int(fields[12])  # utime + stime


def test_a_worker_killed_mid_request(server):
    with httpx.Client(base_url=server.url, timeout=60) as client:
        outcome: dict = {}

        def fit():
            try:
                outcome["status"] = fit_of_head(client).status_code
            except httpx.TransportError as error:
                outcome["error"] = type(error).__name__

        fitting = threading.Thread(target=fit)
        fitting.start()
        until(lambda: computing(client) >= 1)
        # The fit takes about a second: its worker is the one using the CPU now.
        before = {pid: cpu_ticks(pid) for pid in worker_pids(server.process.pid)}
        time.sleep(0.3)
        busy = max(before, key=lambda pid: cpu_ticks(pid) - before[pid])
        os.kill(busy, signal.SIGKILL)
        fitting.join(60)
        # The request on the killed worker is lost (the connection drops, no answer), ...
        assert "error" in outcome, outcome
        # ... the other worker keeps serving, the supervisor replaces the dead one, and the
        # dead worker's jobs in flight are no longer counted. A ping on its way to the killed
        # worker keeps the supervisor waiting up to WORKER_SILENCE_S before it looks again.
        until(lambda: busy not in worker_pids(server.process.pid))
        until(lambda: len(worker_pids(server.process.pid)) >= 2, WORKER_SILENCE_S + 10)
        healthy(client)
        for _ in range(6):
            assert client.get("/v1/samples").status_code == 200
    assert any("died" in e["message"] for e in server.lines())
