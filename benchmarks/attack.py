"""Hostile traffic against ``meshflat serve`` on 127.0.0.1 (``make attack``).

Runs a real server (``--workers`` processes, API keys on) and, one case after another:

* **memory**: each hostile upload of :mod:`fixtures.hostile` (``--size`` bytes) and two
  honest scans, one at a time: the reader's peak allocation per byte of the file (read here,
  under tracemalloc), and the peak resident memory a worker gained while it handled the
  request (from /proc, sampled every 5 ms) against what the job was charged to the memory
  budget (service.server.jobs); and two /v1/points bodies of that size, one of empty objects;
* **planning routes**: the requests of :mod:`benchmarks.attack_planning` (a zig-zag curve,
  a zone of 400,000 points, a palette PNG bomb, 256 nested zones, far corners, a truncated
  density map, a follow-up at 1e40 or 1e-90, a decoy boundary), each with the statuses it may
  answer and what its answer must hold;
* **jobs past their time limit**: six registrations of a 1.13M-face head at once on a
  server whose limit is a few seconds (:mod:`benchmarks.attack_deadline`): how soon after
  their 504s their slots are free, and other jobs served again;
* **slow clients**: ``--slow`` connections at once that send their body at 1 KB/s, that
  declare a Content-Length and stop sending, that send nothing, or that send a header line a
  second; meanwhile a probe posts ``/v1/points`` and a small ``/v1/flatten`` in turn, and
  its statuses and p99 latency are the case's.

Every case ends with a health check: ``/healthz`` and a small flatten answer 200.

Targets (the exit status is 1 when one is missed): every reader at most 8 bytes per byte
uploaded plus 16 MiB; a worker's growth within its job's charge (for the planning routes,
the charge the server logs); slots free, and others served, within 1 s of a late job's 504;
no 500; the probes answer
only 200, p99 under 1 s; the server is healthy after every case. ``--short`` (CI) sends
16 MiB uploads and holds the slow clients for 6 s; ``--write-docs`` records the table in
docs/benchmarks.md.
Traffic goes only to 127.0.0.1; every case is bounded in time and connections.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import os
import platform
import socket
import statistics
import sys
import tempfile
import threading
import time
import tracemalloc
import uuid
from collections import Counter
from dataclasses import dataclass, field

import httpx

from benchmarks.attack_deadline import (
    AT_ONCE,
    LIMIT,
    RELEASE_TARGET,
    long_job,
    refusals_round,
    slots_round,
)
from benchmarks.attack_planning import PlanningCase, planning_cases
from benchmarks.docs import publish
from benchmarks.server import children_of, rss_bytes, serving
from fixtures.hostile import HOSTILE, HOSTILE_JSON
from service.capabilities.context import JSON_BYTES_PER_BYTE, READER_BYTES_PER_BYTE, job_bytes
from service.meshio import Mesh, MeshFormatError, format_of, read_mesh
from service.samples import SAMPLES
from service.settings import Settings

KEY = "attack-key"
HEADERS = {"X-API-Key": KEY}
MiB = 2**20
#: A reader's allowance on top of 8 bytes per byte (its chunk of text, small arrays).
READER_CONSTANT = 16 * MiB
SCALP = {"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}}


@dataclass
class Row:
    case: str
    uploaded: int = 0
    reader: int | None = None  # bytes the reader allocated at its peak (tracemalloc)
    peak: int | None = None  # bytes a worker's RSS grew by
    charged: int | None = None  # what the job is charged to the memory budget
    statuses: Counter = field(default_factory=Counter)
    seconds: float = 0.0
    probe_p99: float | None = None
    probe_statuses: Counter = field(default_factory=Counter)
    healthy: bool = False
    expected: frozenset | None = None  # the statuses a planning case may answer
    held: bool | None = None  # whether its answer held what it must
    free_after: float | None = None  # seconds from the last 504 until the slots were free
    refused_after: float | None = None  # seconds from the last 504 to the last refusal
    logged: bool = False  # whether its charge is read from the server's log

    @property
    def per_byte(self) -> float | None:
        if self.reader is None or not self.uploaded:
            return None
        return self.reader / self.uploaded

    def checks(self) -> dict[str, bool]:
        checks = {"no 500": 500 not in self.statuses, "healthy after": self.healthy}
        if self.reader is not None:
            checks["reader at most 8 B/B + 16 MiB"] = (
                self.reader <= 8 * self.uploaded + READER_CONSTANT
            )
        if self.peak is not None and self.charged is not None:
            checks["worker's growth within its charge"] = self.peak <= self.charged
        elif self.logged:
            checks["its charge logged"] = False
        if self.expected is not None:
            allowed = "/".join(map(str, sorted(self.expected)))
            checks[f"answered {allowed}"] = set(self.statuses) <= self.expected
            checks["its answer right"] = bool(self.held)
        if self.free_after is not None:
            checks[f"slots free within {RELEASE_TARGET:g} s"] = self.free_after <= RELEASE_TARGET
        if self.refused_after is not None:
            checks[f"others refused no later than {RELEASE_TARGET:g} s after"] = (
                self.refused_after <= RELEASE_TARGET
            )
        if self.probe_p99 is not None:
            checks["probes: only 200"] = set(self.probe_statuses) == {200}
            checks["probes: p99 under 1 s"] = self.probe_p99 < 1.0
        return checks

    def line(self) -> str:
        per_byte = f"{self.per_byte:.1f}" if self.per_byte is not None else "-"
        peak = f"{self.peak / MiB:,.0f}" if self.peak is not None else "-"
        charged = f"{self.charged / MiB:,.0f}" if self.charged is not None else "-"
        statuses = ", ".join(f"{s}: {n}" for s, n in sorted(self.statuses.items(), key=str))
        probes = (
            f"{', '.join(f'{s}: {n}' for s, n in sorted(self.probe_statuses.items(), key=str))}; "
            f"p99 {self.probe_p99 * 1e3:.0f} ms"
            if self.probe_p99 is not None
            else "-"
        )
        if self.free_after is not None:
            probes = f"slots free {self.free_after:.2f} s after the last answer"
        if self.refused_after is not None:
            probes = f"last refusal {self.refused_after:+.2f} s from the last answer"
        met = all(self.checks().values())
        return (
            f"| {self.case} | {self.uploaded / MiB:,.1f} | {per_byte} | {peak} | {charged} | "
            f"{statuses} | "
            f"{self.seconds:.2f} s | {probes} | {'yes' if self.healthy else 'NO'} | "
            f"{'met' if met else 'MISSED'} |"
        )


# -- the server's memory ------------------------------------------------------------------


def workers_of(supervisor: int) -> list[int]:
    return children_of(supervisor) or [supervisor]


class Background:
    """A daemon thread running :meth:`_run` for as long as the ``with`` block lasts (until
    ``_stop`` is set)."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        raise NotImplementedError

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *_) -> None:
        self._stop.set()
        self._thread.join()


class PeakWatch(Background):
    """The largest growth of any worker's RSS over its reading at the start, sampled."""

    def __init__(self, supervisor: int) -> None:
        self.pids = workers_of(supervisor)
        self.start = {pid: rss_bytes(pid) for pid in self.pids}
        self.peak = 0
        super().__init__()

    def _run(self) -> None:
        while not self._stop.is_set():
            for pid in self.pids:
                self.peak = max(self.peak, rss_bytes(pid) - self.start[pid])
            time.sleep(0.005)


# -- the cases ------------------------------------------------------------------------------


def healthy(client: httpx.Client) -> bool:
    try:
        if client.get("/healthz").status_code != 200:
            return False
        response = client.post(
            "/v1/flatten",
            files={"mesh": ("head.ply", SAMPLES["fsaverage-head.ply"].path.read_bytes())},
            data={"params": json.dumps(SCALP)},
            headers=HEADERS,
        )
    except httpx.TransportError:
        return False
    return response.status_code == 200


def settle() -> None:
    """Time for an idle worker to give its free heap back (service.server.allocator), so that the
    next case's growth is its own."""
    time.sleep(1.6)


def reader_peak(name: str, data: bytes) -> tuple[int, Mesh | None]:
    """The reader's peak allocation for ``data`` (numpy's arrays included: tracemalloc
    sees them), and the mesh when it reads."""
    tracemalloc.start()
    try:
        mesh = read_mesh(data, format_of(name, None), Settings().limits)
    except MeshFormatError:
        mesh = None
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peak, mesh


def charge_of(body: int, mesh: Mesh | None) -> int:
    """What the service charges the job (service.server.jobs): the body, the reader's allowance and,
    for a mesh that reads, the computation's estimate."""
    charged = (1 + READER_BYTES_PER_BYTE) * body
    return charged + (job_bytes(len(mesh.vertices), len(mesh.faces)) if mesh else 0)


def upload_case(
    client: httpx.Client, server: int, case: str, name: str, data: bytes, params: dict
) -> Row:
    row = Row(case, uploaded=len(data))
    row.reader, mesh = reader_peak(name, data)
    row.charged = charge_of(len(data), mesh)
    del mesh
    return measured(
        client,
        server,
        row,
        lambda: client.post(
            "/v1/flatten",
            files={"mesh": (name, data)},
            data={"params": json.dumps(params)},
            headers=HEADERS,
        ),
    )


def json_case(client: httpx.Client, server: int, case: str, body: bytes) -> Row:
    row = Row(case, uploaded=len(body), charged=(1 + JSON_BYTES_PER_BYTE) * len(body))
    return measured(
        client,
        server,
        row,
        lambda: client.post(
            "/v1/points", content=body, headers=HEADERS | {"Content-Type": "application/json"}
        ),
    )


def measured(client: httpx.Client, server: int, row: Row, send) -> Row:
    """``row`` with the status, time and worker's peak growth of ``send()`` (sent once the
    worker has settled), and the health check after it."""
    settle()
    with PeakWatch(server) as watch:
        started = time.perf_counter()
        try:
            row.statuses[send().status_code] += 1
        except httpx.TransportError as error:
            row.statuses[type(error).__name__] += 1
        row.seconds = time.perf_counter() - started
    row.peak = watch.peak
    row.healthy = healthy(client)
    return row


def planning_case(client: httpx.Client, server: int, case: PlanningCase, log) -> Row:
    """A planning route's hostile request (:mod:`benchmarks.attack_planning`): its status
    among those it may answer, its answer right, and the worker's growth against the charge
    the server's access line gives (``log``: the server's log file)."""
    row = Row(case.name, expected=case.expected, logged=True)
    answers = []
    request_id = f"attack-{uuid.uuid4().hex}"

    def send() -> httpx.Response:
        answers.append(case.send(client, HEADERS | {"X-Request-ID": request_id}))
        row.uploaded = int(answers[-1].request.headers.get("Content-Length", 0))
        return answers[-1]

    measured(client, server, row, send)
    row.held = bool(answers) and case.holds(answers[-1])
    row.charged = charge_logged(log, request_id)
    return row


def charge_logged(log, request_id: str, seconds: float = 5.0) -> int | None:
    """The ``charged_bytes`` of the request's access line in the server's ``log`` (a file
    the server writes to), once it is there; None if it never comes. The file is opened
    anew: reading through the server's own descriptor would move its writing position."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        with open(f"/proc/self/fd/{log.fileno()}", encoding="utf-8", errors="replace") as lines:
            for line in lines:
                if request_id in line and '"message": "request"' in line:
                    return json.loads(line).get("charged_bytes")
        time.sleep(0.05)
    return None


class Probe(Background):
    """Posts /v1/points and a small /v1/flatten in turn until stopped."""

    def __init__(self, url: str) -> None:
        self.url, self.latencies, self.statuses = url, [], Counter()
        super().__init__()
        self._mesh = SAMPLES["fsaverage-head.ply"].path.read_bytes()

    def _run(self) -> None:
        with httpx.Client(base_url=self.url, timeout=30, headers=HEADERS) as client:
            turn = 0
            while not self._stop.is_set():
                started = time.perf_counter()
                try:
                    if turn % 2:
                        response = client.post(
                            "/v1/flatten",
                            files={"mesh": ("head.ply", self._mesh)},
                            data={"params": json.dumps(SCALP)},
                        )
                    else:
                        response = client.post("/v1/points", json={"points": [[1, 2, 3]]})
                    self.statuses[response.status_code] += 1
                except httpx.TransportError as error:
                    self.statuses[type(error).__name__] += 1
                self.latencies.append(time.perf_counter() - started)
                turn += 1
                time.sleep(0.05)

    @property
    def p99(self) -> float:
        if len(self.latencies) < 2:
            return float("nan")
        return statistics.quantiles(self.latencies, n=100)[98]


def _slow_upload(sock: socket.socket, stop: threading.Event, length: int) -> None:
    sock.sendall(
        b"POST /v1/flatten HTTP/1.1\r\nHost: x\r\nX-API-Key: " + KEY.encode() + b"\r\n"
        b"Content-Type: multipart/form-data; boundary=b\r\n"
        b"Content-Length: " + str(length).encode() + b"\r\n\r\n"
    )
    while not stop.wait(0.1):
        sock.sendall(b"v 0 0 0\n" * 12 + b"v 0\n")  # 100 bytes every 0.1 s: 1 KB/s


def _lying_length(sock: socket.socket, stop: threading.Event, length: int) -> None:
    sock.sendall(
        b"POST /v1/flatten HTTP/1.1\r\nHost: x\r\nX-API-Key: " + KEY.encode() + b"\r\n"
        b"Content-Type: multipart/form-data; boundary=b\r\n"
        b"Content-Length: " + str(length).encode() + b"\r\n\r\n" + b"x" * 1024
    )
    stop.wait()


def _silent(sock: socket.socket, stop: threading.Event, length: int) -> None:
    stop.wait()


def _header_drip(sock: socket.socket, stop: threading.Event, length: int) -> None:
    sock.sendall(b"GET /healthz HTTP/1.1\r\n")
    while not stop.wait(1.0):
        sock.sendall(b"X-Drip: 1\r\n")


SLOW = {
    "slow uploads, 1 KB/s": _slow_upload,
    "Content-Length beyond the body": _lying_length,
    "silent connections": _silent,
    "a header line a second": _header_drip,
}


def slow_case(client: httpx.Client, url: str, port: int, case: str, count: int, hold: float):
    """``count`` connections doing ``case`` for ``hold`` seconds while the probe runs; the
    status each connection got (or how it ended)."""
    row = Row(case)
    stop = threading.Event()
    behaviour = SLOW[case]

    def connection() -> None:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=hold + 30) as sock:
                worker = threading.Thread(
                    target=_quietly, args=(behaviour, sock, stop, 1_000_000), daemon=True
                )
                worker.start()
                answer = b""
                with contextlib.suppress(OSError):
                    while chunk := sock.recv(65536):
                        answer += chunk
                row.statuses[int(answer.split()[1]) if answer else "closed"] += 1
        except OSError as error:
            row.statuses[type(error).__name__] += 1

    started = time.perf_counter()
    with Probe(url) as probe:
        threads = [threading.Thread(target=connection, daemon=True) for _ in range(count)]
        for thread in threads:
            thread.start()
        time.sleep(hold)
        stop.set()
        for thread in threads:
            thread.join(hold + 30)
    row.seconds = time.perf_counter() - started
    row.probe_p99, row.probe_statuses = probe.p99, probe.statuses
    row.healthy = healthy(client)
    return row


def deadline_rows(workers: int) -> list[Row]:
    """Six jobs past their time limit at once (:mod:`benchmarks.attack_deadline`), on a
    server of their own whose limit is ``LIMIT``: how soon their slots are free, and how
    soon other jobs are served again."""
    files = long_job()
    settings = {"MESHFLAT_WORKERS": str(workers), "MESHFLAT_API_KEYS": KEY,
                "MESHFLAT_REQUEST_TIMEOUT": str(LIMIT)}  # fmt: skip
    rows = []
    with (
        serving(settings, own_limits=True) as served,
        httpx.Client(base_url=served.url, timeout=120) as client,
    ):
        for what, run in (("slots", slots_round), ("others", refusals_round)):
            case = f"{AT_ONCE} registrations of 1.13M faces past a {LIMIT:g} s limit ({what})"
            found = run(served.url, HEADERS, files)
            row = Row(case, statuses=found.statuses, seconds=found.last_answer,
                      expected=frozenset({503, 504}), held=True)  # fmt: skip
            row.free_after, row.refused_after = found.free_after, found.refused_after
            if what == "slots" and found.free_after is None:
                row.free_after = float("inf")  # not free within a minute
            row.healthy = healthy(client)
            print(row.line(), file=sys.stderr)
            rows.append(row)
    return rows


def _quietly(behaviour, sock, stop, length) -> None:
    with contextlib.suppress(OSError):
        behaviour(sock, stop, length)


# -- the run -------------------------------------------------------------------------------


def honest_scans() -> dict[str, tuple[str, bytes, dict]]:
    """Two real scans, whole: the peak of an honest upload for comparison."""
    return {
        "honest OBJ (Nefertiti, whole)": (
            "head.obj",
            SAMPLES["nefertiti-lowres.obj"].path.read_bytes(),
            {},
        ),
        "honest GLB (Lee Perry-Smith, whole)": (
            "head.glb",
            SAMPLES["lee-perry-smith.glb"].path.read_bytes(),
            {},
        ),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=64 * MiB, help="bytes per hostile upload")
    parser.add_argument("--slow", type=int, default=64, help="slow connections at once")
    parser.add_argument("--hold", type=float, default=15, help="seconds the slow ones last")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--short", action="store_true", help="16 MiB uploads, 6 s holds (CI)")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args(argv)
    if args.short:
        args.size, args.hold = 16 * MiB, 6

    rows: list[Row] = []
    settings = {"MESHFLAT_WORKERS": str(args.workers), "MESHFLAT_API_KEYS": KEY}
    with tempfile.TemporaryFile("w+") as log_file:
        with (
            serving(settings, own_limits=True, log=log_file) as served,
            httpx.Client(base_url=served.url, timeout=120) as client,
        ):
            server = served.process.pid
            for case, (name, build) in HOSTILE.items():
                rows.append(upload_case(client, server, case, name, build(args.size), {}))
                print(rows[-1].line(), file=sys.stderr)
            for case, build in HOSTILE_JSON.items():
                rows.append(json_case(client, server, case, build(args.size)))
                print(rows[-1].line(), file=sys.stderr)
            for case, (name, data, params) in honest_scans().items():
                rows.append(upload_case(client, server, case, name, data, params))
                print(rows[-1].line(), file=sys.stderr)
            for case in planning_cases():
                rows.append(planning_case(client, server, case, log_file))
                print(rows[-1].line(), file=sys.stderr)
            for case in SLOW:
                rows.append(slow_case(client, served.url, served.port, case, args.slow, args.hold))
                print(rows[-1].line(), file=sys.stderr)
        rows += deadline_rows(args.workers)
        log_file.seek(0)
        log = log_file.read()
    plain = [line for line in log.splitlines() if line.strip() and not line.startswith("{")]

    checks = {f"{row.case}: {name}": ok for row in rows for name, ok in row.checks().items()}
    checks["every log line is JSON"] = not plain
    report = "\n".join(
        [
            f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, {platform.machine()}, "
            f"{os.cpu_count()} CPUs (the clients run on the same machine); `meshflat serve` "
            f"with {args.workers} workers, API keys on, default limits; hostile uploads of "
            f"{args.size / MiB:.0f} MiB; {args.slow} slow connections for {args.hold:g} s.",
            "",
            "| case | upload (MiB) | reader's peak / byte | worker's RSS growth (MiB) | charged "
            "(MiB) | statuses | time | probes (/v1/points, small /v1/flatten) | healthy after "
            "| targets |",
            "|---|---:|---:|---:|---:|---|---:|---|---|---|",
            *(row.line() for row in rows),
            "",
            f"Log lines that are not JSON: {len(plain)}.",
            "",
            *(f"* {name}: MISSED" for name, ok in checks.items() if not ok),
            f"* {sum(checks.values())} of {len(checks)} targets met",
        ]
    )
    publish("attack", "Hostile traffic (make attack)", report, args.write_docs)
    return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
