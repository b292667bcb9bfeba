"""``meshflat serve`` as deployed: a real uvicorn with two worker processes on 127.0.0.1,
configured by environment variables only."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest

from fixtures.meshes import subdivided_ply

from .conftest import real_servers
from .test_operations import families, sample

pytestmark = real_servers

KEY = "serve-test-key"
REGION = {"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}}


#: fsaverage-head.ply subdivided four times (1,039,872 faces, a 20 MB PLY): the separable fit
#: of its top (the slowest fit: its angles come from a root search, its gradients from
#: differences) computes for most of a second, long enough to signal or kill the worker
#: while it does.
HEAD = subdivided_ply("fsaverage-head.ply", 4)
SLOW_FIT = REGION | {"method": "separable"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """``meshflat serve`` in a child process; its stderr (the JSON log) kept in a file.

    The server's processes append to the file (O_APPEND) and :meth:`lines` reads it through
    a file of its own: reading through the descriptor they share would move their offset, and
    a line written meanwhile would land over others."""

    def __init__(self, **env: str) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.logs = tempfile.TemporaryDirectory()  # kept after stop(), unlike TMPDIR
        self.log = Path(self.logs.name) / "serve.log"
        self.tmp = tempfile.TemporaryDirectory()
        environ = {k: v for k, v in os.environ.items() if not k.startswith("MESHFLAT_")}
        environ.pop("PROMETHEUS_MULTIPROC_DIR", None)
        environ |= {"MESHFLAT_PORT": str(self.port), "TMPDIR": self.tmp.name, **env}
        self.workers = int(environ.get("MESHFLAT_WORKERS", "1"))
        # Its own process group: the workers go with the supervisor when a test kills both.
        with open(self.log, "ab") as log:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "service.cli", "serve"],
                env=environ,
                stdout=log,
                stderr=log,
                start_new_session=True,
            )

    def wait_ready(self, seconds: float = 60) -> None:
        """Until every worker has started (its log says so) and /readyz answers 200."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            assert self.process.poll() is None, self.lines()
            started = [e for e in self.lines() if e["message"] == "Application startup complete."]
            try:
                ready = httpx.get(f"{self.url}/readyz", timeout=1).status_code == 200
            except httpx.TransportError:
                ready = False
            if ready and len(started) == self.workers:
                return
            time.sleep(0.1)
        raise AssertionError("not ready in time")

    def lines(self) -> list[dict]:
        with open(self.log) as log:  # a line still being written is left for the next read
            return [
                json.loads(line) for line in log if line.startswith("{") and line.endswith("\n")
            ]

    def stop(self) -> int:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        code = self.process.wait(60)
        self.tmp.cleanup()
        return code


@contextmanager
def running(**env: str) -> Iterator[Server]:
    """A ready server with ``env``; killed at the end if it still runs."""
    server = Server(**env)
    try:
        server.wait_ready()
        yield server
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(server.process.pid, signal.SIGKILL)
        server.process.wait()


@pytest.fixture
def two_workers():
    with running(MESHFLAT_WORKERS="2", MESHFLAT_API_KEYS=KEY) as server:
        yield server


def test_two_workers_share_their_metrics_and_stop_gracefully_on_sigterm(two_workers):
    server, headers = two_workers, {"X-API-Key": KEY}
    with httpx.Client(base_url=server.url, timeout=60) as c:
        for _ in range(6):  # spread over both workers by the kernel
            assert c.get("/v1/samples", headers=headers).status_code == 200
        assert c.get("/v1/samples").status_code == 401
        # Whichever worker answers /metrics, the counts are the sum over both.
        for _ in range(4):
            parsed = families(c.get("/metrics").text)
            ok = sample(parsed, "meshflat_requests_total", route="/v1/samples", status="200")
            assert ok == 6
            assert sample(parsed, "meshflat_rejections_total", reason="unauthorized") == 1
        pids = {line.get("message") for line in server.lines()}
        assert sum(m.startswith("Started server process") for m in pids) == 2

        # SIGTERM while a fit computes: the fit is answered, then the server exits 0.
        answer: dict = {}

        def fit():
            answer["response"] = c.post(
                "/v1/fit",
                files={"mesh": ("head.ply", HEAD)},
                data={"params": json.dumps(SLOW_FIT)},
                headers=headers | {"X-Request-ID": "fit-during-stop"},
            )

        fitting = threading.Thread(target=fit)
        fitting.start()
        deadline = time.monotonic() + 10
        while sample(families(c.get("/metrics").text), "meshflat_jobs_computing") < 1:
            assert time.monotonic() < deadline, "the fit was not seen computing"
            time.sleep(0.01)
        server.process.send_signal(signal.SIGTERM)
        fitting.join(60)
    assert answer["response"].status_code == 200, answer["response"].text
    assert server.process.wait(60) == 0
    lines = server.lines()
    sigterm = next(e["time"] for e in lines if e["message"].startswith("Received SIGTERM"))
    fit_line = next(e for e in lines if e.get("request_id") == "fit-during-stop")
    assert fit_line["status"] == 200 and fit_line["time"] > sigterm
    # The workers' metric files lived in a temporary directory, removed at the end.
    assert not any(Path(server.tmp.name).glob("meshflat-metrics-*"))
    server.stop()


def test_one_worker_without_keys_warns_and_a_bad_setting_stops_the_start():
    server = Server()
    try:
        server.wait_ready()
        assert httpx.get(f"{server.url}/v1/samples").status_code == 200
    finally:
        # One worker is uvicorn's server itself: after its graceful shutdown it re-raises the
        # SIGTERM, so the status tells the signal (143 in a shell); the supervisor of several
        # workers exits 0.
        assert server.stop() in (0, -signal.SIGTERM)
    assert any(e["message"] == "Application shutdown complete." for e in server.lines())
    warnings = [e for e in server.lines() if e["level"] == "warning"]
    assert any("no API keys are configured" in e["message"] for e in warnings)

    bad = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve"],
        env=os.environ | {"MESHFLAT_MAX_JOBS": "zero"},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2
    assert "MESHFLAT_MAX_JOBS must be an integer above 0, got 'zero'" in bad.stderr


def test_health_command_is_the_containers_health_check(two_workers):
    command = [sys.executable, "-m", "service.cli", "health"]
    up = subprocess.run(
        command, env=os.environ | {"MESHFLAT_PORT": str(two_workers.port)}, timeout=30
    )
    assert up.returncode == 0
    down = subprocess.run(
        command,
        env=os.environ | {"MESHFLAT_PORT": str(free_port())},
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert down.returncode == 1 and "/healthz" in down.stderr


# -- connections: headers, idle time, framing (service.server.protocol) --------------------


@pytest.fixture(scope="module")
def strict_server():
    with running(MESHFLAT_HEADER_TIMEOUT="0.5", MESHFLAT_KEEP_ALIVE_TIMEOUT="0.5") as server:
        yield server


def read_all(connection: socket.socket, seconds: float = 5) -> tuple[bytes, float]:
    """What the server sends until it closes the connection, and when it closed it."""
    connection.settimeout(seconds)
    started, received = time.monotonic(), b""
    while chunk := connection.recv(65536):
        received += chunk
    return received, time.monotonic() - started


def problem_of(raw: bytes) -> tuple[int, dict[str, str], dict]:
    head, _, body = raw.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    headers = dict(line.lower().split(": ", 1) for line in lines[1:])
    return int(lines[0].split()[1]), headers, json.loads(body)


def test_a_silent_connection_is_closed_at_the_header_time_limit(strict_server):
    with socket.create_connection(("127.0.0.1", strict_server.port)) as connection:
        received, seconds = read_all(connection)
    assert received == b"" and 0.4 < seconds < 3


def test_headers_sent_a_line_at_a_time_get_a_408_at_the_limit(strict_server):
    with socket.create_connection(("127.0.0.1", strict_server.port)) as connection:
        connection.sendall(b"GET /healthz HTTP/1.1\r\n")
        started = time.monotonic()
        for _ in range(3):
            time.sleep(0.2)
            with contextlib.suppress(OSError):
                connection.sendall(b"X-Slow: 1\r\n")
        received, _ = read_all(connection)
    status, headers, body = problem_of(received)
    assert status == 408 and headers["content-type"] == "application/problem+json"
    assert "MESHFLAT_HEADER_TIMEOUT" in body["detail"] and headers["connection"] == "close"
    assert time.monotonic() - started < 3


def test_an_idle_kept_alive_connection_is_closed(strict_server):
    with socket.create_connection(("127.0.0.1", strict_server.port)) as connection:
        connection.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        received, seconds = read_all(connection)
    assert received.startswith(b"HTTP/1.1 200") and 0.4 < seconds < 3


def test_malformed_framing_is_answered_with_a_problem(strict_server):
    with socket.create_connection(("127.0.0.1", strict_server.port)) as connection:
        connection.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nContent-Length: -4\r\n\r\n")
        received, _ = read_all(connection)
    status, headers, body = problem_of(received)
    assert status == 400 and headers["content-type"] == "application/problem+json"
    assert body["type"].endswith("malformed-request") and "not valid HTTP/1.1" in body["detail"]


def test_a_full_service_refuses_before_the_body_and_closes():
    """The headers of an upload that cannot be admitted are answered at once; the client
    that sent `Expect: 100-continue` never sends its body."""
    with running(MESHFLAT_MAX_UPLOADS="1", MESHFLAT_UPLOAD_GRACE="30") as server:
        with socket.create_connection(("127.0.0.1", server.port)) as holder:
            holder.sendall(
                b"POST /v1/points HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                b"Content-Length: 100\r\n\r\n{"
            )
            time.sleep(0.3)
            with socket.create_connection(("127.0.0.1", server.port)) as refused:
                refused.sendall(
                    b"POST /v1/points HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                    b"Content-Length: 1000000\r\nExpect: 100-continue\r\n\r\n"
                )
                received, seconds = read_all(refused)
            # One that sends its whole body before reading gets the same answer, not a reset.
            with socket.create_connection(("127.0.0.1", server.port)) as eager:
                eager.sendall(
                    b"POST /v1/points HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                    b"Content-Length: 4000000\r\n\r\n" + b" " * 4_000_000
                )
                eager_received, _ = read_all(eager)
    status, headers, body = problem_of(received)
    assert status == 503 and headers["connection"] == "close" and "retry-after" in headers
    assert "1 request bodies are arriving" in body["detail"] and seconds < 2
    eager_status, eager_headers, eager_body = problem_of(eager_received)
    assert (eager_status, eager_body) == (status, body) and "retry-after" in eager_headers


def test_an_answer_before_the_body_ends_the_connection(strict_server):
    """A 401 or 404 sent before the body is read closes the connection: the rest of the body
    is not read at the client's pace (here a 404 to a body that never comes)."""
    with socket.create_connection(("127.0.0.1", strict_server.port)) as connection:
        connection.sendall(b"POST /nowhere HTTP/1.1\r\nHost: x\r\nContent-Length: 100000\r\n\r\n")
        received, seconds = read_all(connection)
    assert received.startswith(b"HTTP/1.1 404") and seconds < 2


def test_a_client_that_sends_its_whole_body_before_reading_gets_the_early_answer(strict_server):
    """The connection ends with a lingering close: the 8 MiB this client writes after its
    404 was sent are read and dropped, so it reads the answer, not a reset."""
    with socket.create_connection(("127.0.0.1", strict_server.port)) as connection:
        size = 8 * 2**20
        connection.sendall(
            f"POST /nowhere HTTP/1.1\r\nHost: x\r\nContent-Length: {size}\r\n\r\n".encode()
        )
        connection.sendall(bytes(size))
        received, seconds = read_all(connection)
    assert received.startswith(b"HTTP/1.1 404") and received.endswith(b"}") and seconds < 2


def seconds_until_cut_off(port: int) -> float | None:
    """How long a client that keeps sending a body after its early answer (a 404) may go on
    before the connection is closed on it (None: not within 10 s)."""
    with socket.create_connection(("127.0.0.1", port)) as connection:
        connection.sendall(
            b"POST /nowhere HTTP/1.1\r\nHost: x\r\nContent-Length: 10000000000\r\n\r\n"
        )
        started = time.monotonic()
        while time.monotonic() - started < 10:
            try:
                connection.sendall(bytes(4096))
            except OSError:
                return time.monotonic() - started
            time.sleep(0.05)
    return None


def test_a_lingering_connection_is_closed_when_its_client_keeps_sending(strict_server):
    """Lingering is bounded: a client that keeps sending after its early answer is cut off
    after MESHFLAT_LINGERING_CLOSE (2 s by default)."""
    cut = seconds_until_cut_off(strict_server.port)
    assert cut is not None and 1.5 < cut < 4


def test_behind_an_ingress_the_header_timer_and_the_lingering_close_can_be_switched_off():
    """MESHFLAT_HEADER_TIMEOUT=0 and MESHFLAT_LINGERING_CLOSE=0, for an ingress that does
    both: a silent connection is left open, and an early answer closes its connection at
    once (the client that keeps sending is cut off well before the lingering's 2 s)."""
    with running(MESHFLAT_HEADER_TIMEOUT="0", MESHFLAT_LINGERING_CLOSE="0") as server:
        with socket.create_connection(("127.0.0.1", server.port)) as silent:
            silent.settimeout(1.5)
            with pytest.raises(TimeoutError):
                silent.recv(1)  # no header timer: nothing comes, the connection stays
            silent.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
            received, _ = read_all(silent)
        assert received.startswith(b"HTTP/1.1 200")
        cut = seconds_until_cut_off(server.port)
    assert cut is not None and cut < 1.2


def test_serve_seeds_numba_with_the_image_s_compiled_kernels_once(tmp_path, monkeypatch):
    """The image's kernels are copied into NUMBA_CACHE_DIR where it lacks them (its empty
    directories made by importing the kernels), and a kernel it has is left as it is."""
    from service.cli import _seed_compiled_kernels

    built = tmp_path / "built" / "opt" / "transforms"
    built.mkdir(parents=True)
    (built / "kernel.nbi").write_bytes(b"index")
    cache = tmp_path / "cache"
    (cache / "opt" / "transforms").mkdir(parents=True)  # as importing the kernels leaves it
    monkeypatch.setenv("MESHFLAT_KERNELS_FROM", str(tmp_path / "built"))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    _seed_compiled_kernels()
    assert (cache / "opt" / "transforms" / "kernel.nbi").read_bytes() == b"index"
    (built / "kernel.nbi").write_bytes(b"newer")
    _seed_compiled_kernels()
    assert (cache / "opt" / "transforms" / "kernel.nbi").read_bytes() == b"index"
