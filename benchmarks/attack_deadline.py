"""Six jobs past their time limit at once, for ``make attack`` (benchmarks/attack.py).

A server of its own (``--workers`` processes, API keys, default limits but a time limit of
``LIMIT`` seconds) gets six registrations of the 1.13M-face head (Lee Perry-Smith split
three times) to itself at once: each computes for several times the limit, and together
they take every compute slot and every place in the queues. Each must answer 504 at its
limit (or 503 at once, when its worker had no room), and its computation must stop at its
next checkpoint (``transforms/checkpoints.py``) and give its slot back.

Two rounds: the first polls ``/metrics`` until no job computes or is in flight, and gives
how long after the last 504 the slots were free; the second sends a small job every 50 ms
meanwhile, and gives how long after the last 504 it was still refused. Targets: slots free
within 1 s of the last 504, and other jobs refused no later than that.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from dataclasses import dataclass

import httpx
from prometheus_client.parser import text_string_to_metric_families

from fixtures.meshes import subdivided_ply

#: The server's time limit (MESHFLAT_REQUEST_TIMEOUT), seconds.
LIMIT = 3.0
#: Jobs sent at once: each worker's slots and queue (MESHFLAT_MAX_JOBS + MAX_WAITING), two
#: workers.
AT_ONCE = 6
#: How long the slots may stay taken after the last 504, seconds.
RELEASE_TARGET = 1.0


@dataclass
class DeadlineRound:
    statuses: Counter
    last_answer: float  # seconds from the start to the last of the six answers
    free_after: float | None = None  # seconds from the last answer until no job held a slot
    refused_after: float | None = None  # seconds from the last answer to the last refusal


def long_job() -> dict:
    """The files of a registration that computes for several times ``LIMIT``."""
    head = subdivided_ply("lee-perry-smith.glb", 3)
    return {"baseline": ("b.ply", head), "follow_up": ("f.ply", head)}


def _gauges(client: httpx.Client) -> tuple[float, float]:
    """Jobs computing and jobs in flight, summed over the workers."""
    found = {"meshflat_jobs_computing": 0.0, "meshflat_jobs_in_flight": 0.0}
    for family in text_string_to_metric_families(client.get("/metrics").text):
        for sample in family.samples:
            if sample.name in found:
                found[sample.name] += sample.value
    return found["meshflat_jobs_computing"], found["meshflat_jobs_in_flight"]


def _six_at_once(url: str, headers: dict, files: dict, started: float) -> tuple[Counter, float]:
    """The six jobs sent together; their statuses and when the last one answered."""
    statuses: Counter = Counter()
    answered = []
    lock = threading.Lock()

    def send() -> None:
        with httpx.Client(base_url=url, timeout=120, headers=headers) as client:
            try:
                status = client.post("/v1/register", files=files, data={"params": "{}"}).status_code
            except httpx.TransportError as error:
                status = type(error).__name__
        with lock:
            statuses[status] += 1
            answered.append(time.perf_counter() - started)

    threads = [threading.Thread(target=send) for _ in range(AT_ONCE)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return statuses, max(answered)


def slots_round(url: str, headers: dict, files: dict) -> DeadlineRound:
    """The six, then ``/metrics`` polled until no job computes or is in flight."""
    started = time.perf_counter()
    statuses, last = _six_at_once(url, headers, files, started)
    with httpx.Client(base_url=url, timeout=10) as client:
        while any(_gauges(client)):
            if time.perf_counter() - started > last + 60:
                return DeadlineRound(statuses, last)
            time.sleep(0.02)
    return DeadlineRound(statuses, last, time.perf_counter() - started - last)


def refusals_round(url: str, headers: dict, files: dict) -> DeadlineRound:
    """The six, with a small /v1/points job every 50 ms from their start until 3 s after
    the last answered; when the last of those was refused."""
    started = time.perf_counter()
    stop = threading.Event()
    refused: list[float] = []

    def probe() -> None:
        with httpx.Client(base_url=url, timeout=30, headers=headers) as client:
            while not stop.is_set():
                sent = time.perf_counter() - started
                try:
                    ok = client.post("/v1/points", json={"points": [[1, 2, 3]]}).status_code
                except httpx.TransportError:
                    ok = 0
                if ok != 200:
                    refused.append(sent)
                time.sleep(0.05)

    prober = threading.Thread(target=probe)
    prober.start()
    statuses, last = _six_at_once(url, headers, files, started)
    time.sleep(3.0)
    stop.set()
    prober.join()
    return DeadlineRound(statuses, last, refused_after=max(refused, default=0.0) - last)
