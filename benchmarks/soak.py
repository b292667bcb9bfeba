"""Load and soak test of ``meshflat serve`` on 127.0.0.1 (``make soak``).

A bundled scan is made into a mesh of about 100,000 faces (lee-perry-smith.glb subdivided
once, then its top faces once more) and posted to ``/v1/flatten`` in a mix of requests (the
scalp or the whole head; JSON, GLB, SVG or PNG answers):

1. at capacity: as many clients as the server admits at once, the most it serves without a
   503 (``--workers`` x (MESHFLAT_MAX_JOBS + MESHFLAT_MAX_WAITING)), for ``--duration``
   seconds (15);
2. at ``--overload`` (8) times capacity for ``--overload-duration`` seconds (15); a client
   that gets a 503 waits the ``Retry-After`` it was given, then sends again;

the two in turn for ``--rounds`` (6) rounds, so that a drift of the machine's speed falls on
both loads alike, and each load's rounds added up.

Each client is a thread with its own connection; the clients run at nice 10, below the
server, so that on a machine they share they take the CPU it leaves. Reported per load:
requests, goodput (200s a second), latency p50/p95/p99 of the 200s, statuses, transport
errors, the CPU seconds a second of the server's processes and of the clients', how busy
the compute slots were and their time per 200; the ratio of goodputs round by round; and the
resident memory of the server's processes (the supervisor and its workers, from /proc) 2 s
after a warm-up at capacity and 2 s after each round, and every 5 s under load.

Targets (the exit status is 1 when one is missed): only 200 at capacity; only 200 and 503
beyond it, every 503 with ``Retry-After``; goodput beyond capacity at least 90 % of goodput
at capacity, and p99 of its 200s at most 1.5 times; no transport error; memory growth from
the warm-up to the end under 10 % (these three judged in the full run only: one round
cannot tell them from noise). ``--short`` runs one round (CI); ``--write-docs`` records the
table in docs/benchmarks.md. The load goes only to 127.0.0.1 and stops at its deadlines.
"""

from __future__ import annotations

import argparse
import datetime
import io
import json
import os
import platform
import statistics
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

import httpx
import numpy as np
import trimesh
from trimesh.remesh import subdivide

from benchmarks.docs import publish
from benchmarks.server import children_of, cpu_seconds, rss_bytes, serving
from service.samples import SAMPLES
from service.settings import Settings

FRAME = {"center": [0, 1.2, -0.3], "rotation": {"pole": [0, -1, 0], "up": [0, 0, 1]}}
SCALP = {"region": {"cone": {"axis": [0, 1, 0], "half_angle_deg": 60, "apex": [0, 1.2, -0.3]}}}
#: The request mix, cycled by each client from its own starting point.
MIX = [
    FRAME | SCALP,
    FRAME | SCALP | {"output": "glb"},
    FRAME,
    FRAME | SCALP | {"output": "png"},
    FRAME | SCALP,
    FRAME | {"output": "glb"},
    FRAME | SCALP | {"output": "svg"},
    FRAME | SCALP,
]


def soak_mesh(faces_wanted: int = 100_000) -> tuple[bytes, int]:
    """The GLB of a bundled scan with about ``faces_wanted`` faces, and its face count."""
    data = SAMPLES["lee-perry-smith.glb"].path.read_bytes()
    mesh = trimesh.load(io.BytesIO(data), file_type="glb", process=False, force="mesh")
    vertices, faces = subdivide(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    top = np.argsort(-vertices[faces].mean(axis=1)[:, 1])  # the scalp: denser, as scans are
    extra = max(0, (faces_wanted - len(faces) + 2) // 3)
    vertices, faces = subdivide(vertices, faces, face_index=top[:extra])
    glb = trimesh.Trimesh(vertices, faces, process=False).export(file_type="glb")
    return glb, len(faces)


def server_pids(supervisor: int) -> list[int]:
    """The supervisor and its children (the workers)."""
    return [supervisor, *children_of(supervisor)]


def rss_mib(supervisor: int) -> float:
    """Resident memory of the supervisor and its children, MiB."""
    return sum(map(rss_bytes, server_pids(supervisor))) / 2**20


def compute_seconds(url: str) -> float:
    """The server's ``meshflat_compute_seconds_total``: busy seconds of its compute slots."""
    metrics = httpx.get(f"{url}/metrics", timeout=10).text
    line = next(line for line in metrics.splitlines() if line.startswith("meshflat_compute_sec"))
    return float(line.split()[-1])


def server_cpu_seconds(supervisor: int) -> float:
    """CPU time of the supervisor and its live children so far, seconds."""
    return sum(map(cpu_seconds, server_pids(supervisor)))


@dataclass
class Phase:
    name: str
    clients: int
    seconds: float
    answers: list[tuple[float, int]] = field(default_factory=list)  # (seconds, status)
    statuses: Counter = field(default_factory=Counter)
    without_retry_after: int = 0
    transport_errors: Counter = field(default_factory=Counter)
    elapsed: float = 0.0
    rss: list[float] = field(default_factory=list)  # MiB, every 5 s
    server_cpu: float = 0.0  # CPU seconds a second: the server's processes
    client_cpu: float = 0.0  # and this one's (the clients')
    compute: float = 0.0  # busy seconds of the compute slots
    slots: int = 1

    def quantile(self, q: int) -> float:
        """The ``q``-th percentile of the 200s' latencies, seconds."""
        ok = sorted(seconds for seconds, status in self.answers if status == 200)
        return statistics.quantiles(ok, n=100)[q - 1] if len(ok) >= 2 else float("nan")

    @property
    def goodput(self) -> float:
        return self.statuses[200] / self.elapsed

    def row(self) -> str:
        done = sum(self.statuses.values())
        q = [self.quantile(k) for k in range(1, 100)]
        statuses = ", ".join(f"{s}: {n:,}" for s, n in sorted(self.statuses.items()))
        errors = sum(self.transport_errors.values())
        return (
            f"| {self.name} | {self.clients} | {self.elapsed:.0f} s | {done:,} | "
            f"{self.goodput:.1f} | {q[49] * 1e3:.0f} | {q[94] * 1e3:.0f} | "
            f"{q[98] * 1e3:.0f} | {statuses} | {self.without_retry_after} | {errors} | "
            f"{self.server_cpu:.2f} | {self.client_cpu:.2f} | "
            f"{self.compute / (self.elapsed * self.slots):.0%} | "
            f"{self.compute / max(1, self.statuses[200]) * 1e3:.0f} |"
        )

    def __post_init__(self) -> None:
        self._lock = threading.Lock()

    @classmethod
    def pooled(cls, phases: list[Phase]) -> Phase:
        """The phases (rounds of one load) as one: their answers and times added up."""
        first = phases[0]
        pooled = cls(first.name, first.clients, sum(p.seconds for p in phases))
        pooled.slots, pooled.compute = first.slots, sum(p.compute for p in phases)
        for phase in phases:
            pooled.answers += phase.answers
            pooled.statuses += phase.statuses
            pooled.without_retry_after += phase.without_retry_after
            pooled.transport_errors += phase.transport_errors
            pooled.rss += phase.rss
        pooled.elapsed = sum(p.elapsed for p in phases)
        pooled.server_cpu = sum(p.server_cpu * p.elapsed for p in phases) / pooled.elapsed
        pooled.client_cpu = sum(p.client_cpu * p.elapsed for p in phases) / pooled.elapsed
        return pooled

    def add(self, seconds: float, status: int, retry_after: bool) -> None:
        with self._lock:
            self.answers.append((seconds, status))
            self.statuses[status] += 1
            if status == 503 and not retry_after:
                self.without_retry_after += 1

    def error(self, kind: str) -> None:
        with self._lock:
            self.transport_errors[kind] += 1


def encoded_mix(mesh: bytes) -> list[tuple[bytes, dict[str, str]]]:
    """The multipart body and headers of each request of the mix, built once: the clients
    share the server's CPUs, so they should spend as little of them as they can."""
    bodies = []
    for params in MIX:
        request = httpx.Request(
            "POST",
            "http://soak/v1/flatten",
            files={"mesh": ("head.glb", mesh)},
            data={"params": json.dumps(params)},
        )
        bodies.append((request.read(), {"Content-Type": request.headers["Content-Type"]}))
    return bodies


def run_phase(url: str, mesh: bytes, phase: Phase, server: int) -> None:
    deadline = time.monotonic() + phase.seconds
    mix = encoded_mix(mesh)

    def client(start: int) -> None:
        with httpx.Client(base_url=url, timeout=120) as http:
            turn = start
            while time.monotonic() < deadline:
                body, headers = mix[turn % len(mix)]
                turn += 1
                began = time.perf_counter()
                try:
                    response = http.post("/v1/flatten", content=body, headers=headers)
                except httpx.TransportError as error:
                    phase.error(type(error).__name__)
                    continue
                retry_after = response.headers.get("retry-after")
                phase.add(time.perf_counter() - began, response.status_code, bool(retry_after))
                if response.status_code == 503 and retry_after:
                    # As a well-behaved client does; never past the phase's end.
                    time.sleep(min(float(retry_after), max(0.0, deadline - time.monotonic())))

    def sample() -> None:
        while time.monotonic() < deadline:
            time.sleep(min(5.0, max(0.0, deadline - time.monotonic())))
            phase.rss.append(rss_mib(server))

    threads = [threading.Thread(target=client, args=(i,)) for i in range(phase.clients)]
    threads.append(threading.Thread(target=sample))
    compute = compute_seconds(url)
    server_cpu, client_cpu = server_cpu_seconds(server), time.process_time()
    started = time.monotonic()
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    phase.elapsed = time.monotonic() - started
    phase.server_cpu = (server_cpu_seconds(server) - server_cpu) / phase.elapsed
    phase.client_cpu = (time.process_time() - client_cpu) / phase.elapsed
    phase.compute = compute_seconds(url) - compute


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--duration", type=float, default=15, help="at capacity, each round")
    parser.add_argument("--overload-duration", type=float, default=15, help="each round")
    parser.add_argument("--overload", type=int, default=8, help="times capacity")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--short", action="store_true", help="one round of 15 s + 15 s (CI)")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args(argv)
    if args.short:
        args.rounds, args.duration, args.overload_duration = 1, 15, 15
    settings = Settings.from_env()
    capacity = args.workers * (settings.max_jobs + settings.max_waiting)
    slots = args.workers * settings.max_jobs

    mesh, faces = soak_mesh()
    rounds: list[tuple[Phase, Phase]] = []
    # The limits given in the environment are the server's (the defaults otherwise).
    with serving({"MESHFLAT_WORKERS": str(args.workers)}, own_limits=False) as served:
        url, server = served.url, served.process
        # The clients share the server's CPUs here, and need three times the CPU beyond
        # capacity that they need at it; at a lower priority than the server's (which has
        # started), they take what it leaves, as clients on other machines would.
        os.nice(10)
        # The warm-up is the first phase's load: the heap (kept, not trimmed: see
        # service/server/allocator.py) reaches its working size before the first reading.
        warm = Phase("warm-up", capacity, 5 if args.short else 15)
        run_phase(url, mesh, warm, server.pid)
        # Each reading after 2 s without requests (an idle worker returns its free heap
        # after 1 s); the readings under load are in the phases' series.
        time.sleep(2)
        rss = [rss_mib(server.pid)]
        for _ in range(args.rounds):
            # The two loads alternate, so that a drift of the machine's speed falls on both.
            below = Phase("at capacity", capacity, args.duration, slots=slots)
            run_phase(url, mesh, below, server.pid)
            beyond = Phase(
                f"{args.overload}x capacity",
                args.overload * capacity,
                args.overload_duration,
                slots=slots,
            )
            run_phase(url, mesh, beyond, server.pid)
            rounds.append((below, beyond))
            time.sleep(2)
            rss.append(rss_mib(server.pid))

    below, beyond = (Phase.pooled([phases[k] for phases in rounds]) for k in (0, 1))
    per_round = ", ".join(f"{b.goodput / a.goodput:.0%}" for a, b in rounds)
    growth = rss[-1] / rss[0] - 1
    goodput, p99 = beyond.goodput / below.goodput, beyond.quantile(99) / below.quantile(99)
    checks = {
        "at capacity: only 200": set(below.statuses) == {200},
        "beyond capacity: only 200 and 503": set(beyond.statuses) <= {200, 503},
        "beyond capacity: some 503": beyond.statuses[503] > 0,
        "every 503 has Retry-After": below.without_retry_after + beyond.without_retry_after == 0,
        "no transport error": not (below.transport_errors or beyond.transport_errors),
    }
    # 15 s cannot tell drift from the heap's composition at the moment it is trimmed (short
    # runs read +0 % to +9 %): the full run judges memory; --short reports it.
    ratios = {
        f"beyond capacity: goodput at least 90 % of capacity's ({goodput:.0%})": goodput >= 0.9,
        f"beyond capacity: p99 at most 1.5x capacity's ({p99:.2f}x)": p99 <= 1.5,
        "memory growth under 10 %": growth < 0.10,
    }
    if args.short:
        # One round of 15 s cannot tell these from noise (runs on one machine read goodput
        # from 76 % to 110 % and p99 from 1.2x to 2.4x): the full run judges them over
        # alternating rounds, --short reports.
        report_only = {
            f"{name} (reported, judged in the full run)": ok for name, ok in ratios.items()
        }
    else:
        checks |= ratios
        report_only = {}
    report = "\n".join(
        [
            f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, {platform.machine()}, "
            f"{os.cpu_count()} CPUs (the clients run on the same machine); `meshflat serve` "
            f"with {args.workers} worker(s), limits MESHFLAT_MAX_JOBS "
            f"{settings.max_jobs} + MESHFLAT_MAX_WAITING {settings.max_waiting} per worker "
            f"(capacity {capacity} clients); {args.rounds} round(s) of {args.duration:.0f} s at "
            f"capacity then {args.overload_duration:.0f} s beyond it, added up below; "
            f"mesh: {faces:,} faces, {len(mesh):,}-byte GLB; mix: "
            "scalp or whole head, JSON, GLB, SVG or PNG; a client waits Retry-After after a 503.",
            "",
            "| phase | clients | time | requests | goodput (200/s) | p50 (ms) | p95 (ms) "
            "| p99 (ms) "
            "| statuses | 503 without Retry-After | transport errors | server CPU (s/s) "
            "| client CPU (s/s) | slots busy | compute per 200 (ms) |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|",
            below.row(),
            beyond.row(),
            "",
            f"Goodput beyond capacity over goodput at capacity, round by round: {per_round}. "
            f"CPU is seconds a second over the phase ({os.cpu_count()} CPUs in all): the "
            "server's processes, and the clients' one. Slots busy: the compute slots' busy "
            "time (meshflat_compute_seconds_total) over their number times the phase's time.",
            "",
            f"Server memory (RSS of the supervisor and workers, 2 s after the load stops): "
            f"{rss[0]:.0f} MiB after the warm-up, {rss[1]:.0f} MiB after the first round, "
            f"{rss[-1]:.0f} MiB at the end ({growth:+.1%}). Under load, every 5 s: at capacity "
            f"{', '.join(f'{m:.0f}' for m in below.rss)}; beyond "
            f"{', '.join(f'{m:.0f}' for m in beyond.rss)} MiB. Latencies are of the 200 answers.",
            "",
            *(f"* {name}: {'met' if ok else 'MISSED'}" for name, ok in checks.items()),
            *(f"* {name}: {'met' if ok else 'not met'}" for name, ok in report_only.items()),
        ]
    )
    publish("soak", "Load and soak (make soak)", report, args.write_docs)
    return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
