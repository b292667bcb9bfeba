"""Running the service for others: API keys, CORS, backpressure, time limits, request ids,
metrics and JSON logs, through the ASGI app."""

from __future__ import annotations

import io
import json
import logging
import logging.config
import sys
import threading
import time
import warnings
from functools import partial

import anyio
import httpx
import orjson
import pytest
from prometheus_client.parser import text_string_to_metric_families
from starlette.responses import Response

from service import routes
from service.app import create_app
from service.observability import JsonFormatter, capture_warnings, log_config
from service.problems import Problem
from service.samples import SAMPLES
from service.server import admission
from service.server.auth import KeyCheck
from service.server.jobs import Deadline, JobGate, TimeLimit
from service.settings import Settings
from service.timings import Timings

from .conftest import load_sample
from .test_api import flatten, problem

pytestmark = pytest.mark.anyio

KEY = "key-for-tests-0123456789"
HEAD = "fsaverage-head.ply"
POINTS = {"points": [[1.0, 0.0, 0.0]]}


def client_of(settings: Settings) -> httpx.AsyncClient:
    app = create_app(settings)
    return httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://m")


# -- settings ------------------------------------------------------------------------------


def test_settings_from_the_environment(tmp_path):
    keys = tmp_path / "keys"
    keys.write_text("from-file-1\n\n  from-file-2  \n")
    settings = Settings.from_env(
        {
            "MESHFLAT_API_KEYS": "a, b,,",
            "MESHFLAT_API_KEYS_FILE": str(keys),
            "MESHFLAT_CORS_ORIGINS": "https://planner.example.com",
            "MESHFLAT_REQUEST_TIMEOUT": "2.5",
            "MESHFLAT_MAX_WAITING": "3",
            "MESHFLAT_HOST": "0.0.0.0",
        }
    )
    assert settings.api_keys == ("a", "b", "from-file-1", "from-file-2")
    assert settings.cors_origins == ("https://planner.example.com",)
    assert settings.request_timeout == 2.5 and settings.max_waiting == 3
    assert settings.host == "0.0.0.0"


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("MESHFLAT_MAX_JOBS", "0", "MESHFLAT_MAX_JOBS must be an integer above 0"),
        ("MESHFLAT_MAX_WAITING", "1.5", "MESHFLAT_MAX_WAITING must be an integer 0 or more"),
        ("MESHFLAT_MAX_WAITING", "-1", "MESHFLAT_MAX_WAITING must be an integer 0 or more"),
        ("MESHFLAT_REQUEST_TIMEOUT", "nan", "MESHFLAT_REQUEST_TIMEOUT must be a number above 0"),
        ("MESHFLAT_REQUEST_TIMEOUT", "inf", "MESHFLAT_REQUEST_TIMEOUT must be a number above 0"),
        ("MESHFLAT_API_KEYS_FILE", "/no/such/file", "MESHFLAT_API_KEYS_FILE: cannot read"),
    ],
)
def test_bad_settings_are_named(name, value, message):
    with pytest.raises(ValueError, match=message):
        Settings.from_env({name: value})


# -- API keys ------------------------------------------------------------------------------


async def test_v1_routes_need_a_key_when_keys_are_configured():
    async with client_of(Settings(api_keys=("other", KEY))) as c:
        for headers, why in (({}, "no API key was sent"), ({"X-API-Key": "nope"}, "not valid")):
            for call in (
                c.get("/v1/samples", headers=headers),
                c.get("/v1/samples/fsaverage-head.ply", headers=headers),
                c.post("/v1/points", json=POINTS, headers=headers),
            ):
                response = await call
                body = problem(response, 401, "Authorization")
                assert why in body["detail"] and "X-API-Key" in body["detail"]
                assert response.headers["www-authenticate"].startswith("Bearer")
        for headers in (
            {"X-API-Key": KEY},
            {"Authorization": f"Bearer {KEY}"},
            {"Authorization": f"bearer {KEY}"},
        ):
            response = await c.post("/v1/points", json=POINTS, headers=headers)
            assert response.status_code == 200, response.text
        problem(await c.get("/v1/samples", headers={"Authorization": f"Basic {KEY}"}), 401)
        # Open: health, readiness (not ready: the lifespan has not run), metrics, the page.
        for path, status in (("/healthz", 200), ("/readyz", 503), ("/metrics", 200), ("/", 200)):
            assert (await c.get(path)).status_code == status, path
        assert (await c.get("/openapi.json")).json()["paths"]["/v1/flatten"]["post"][
            "security"
        ] == [{"bearer": []}, {"apiKey": []}]


async def test_without_keys_the_routes_are_open_and_the_log_says_so(caplog):
    app = create_app(Settings())
    with caplog.at_level(logging.WARNING, logger="meshflat"):
        async with app.router.lifespan_context(app):
            transport = httpx.ASGITransport(app=app)
            async with httpx.AsyncClient(transport=transport, base_url="http://m") as c:
                assert (await c.post("/v1/points", json=POINTS)).status_code == 200
    assert any("no API keys are configured" in r.getMessage() for r in caplog.records)


def test_the_key_check_holds_digests_and_accepts_any_configured_key():
    check = KeyCheck(("first", KEY))
    assert KEY not in repr(vars(check)) and "first" not in repr(vars(check))
    assert KEY not in repr(Settings(api_keys=(KEY,)))
    assert check.accepts(KEY.encode()) and check.accepts(b"first")
    assert not check.accepts(KEY[:-1].encode()) and not check.accepts(b"")
    assert not KeyCheck(())


# -- CORS ----------------------------------------------------------------------------------


async def test_cors_allows_only_the_configured_origins():
    origin = "https://planner.example.com"
    async with client_of(Settings(api_keys=(KEY,), cors_origins=(origin,))) as c:
        preflight = {
            "Origin": origin,
            "Access-Control-Request-Method": "POST",
            "Access-Control-Request-Headers": "authorization, content-type, x-request-id",
        }
        response = await c.options("/v1/flatten", headers=preflight)
        assert response.status_code == 200
        assert response.headers["access-control-allow-origin"] == origin
        allowed = response.headers["access-control-allow-headers"].lower()
        assert {"authorization", "x-api-key", "content-type", "x-request-id"} <= {
            h.strip() for h in allowed.split(",")
        }
        # The answers carry the header too, refusals included, so the page can read them.
        refused = await c.post("/v1/points", json=POINTS, headers={"Origin": origin})
        assert refused.status_code == 401
        assert refused.headers["access-control-allow-origin"] == origin
        assert "x-request-id" in refused.headers["access-control-expose-headers"].lower()

        stranger = preflight | {"Origin": "https://elsewhere.example.org"}
        response = await c.options("/v1/flatten", headers=stranger)
        assert response.status_code == 400
        assert "access-control-allow-origin" not in response.headers
        response = await c.get("/healthz", headers={"Origin": stranger["Origin"]})
        assert "access-control-allow-origin" not in response.headers


# -- backpressure and time limits ----------------------------------------------------------


def held_body(release: anyio.Event):
    """A JSON body whose last byte waits for ``release``."""

    async def body():
        yield b'{"points": [[1, 0, 0]]'
        await release.wait()
        yield b"}"

    return body()


async def post_held(client: httpx.AsyncClient, release: anyio.Event) -> httpx.Response:
    """A /v1/points request whose body ends when ``release`` is set."""
    return await client.post(
        "/v1/points", content=held_body(release), headers={"content-type": "application/json"}
    )


async def test_slow_uploads_hold_no_compute_slot_and_are_bounded_apart():
    """Two bodies still arriving fill MESHFLAT_MAX_UPLOADS=2 but hold no job slot: a third
    upload is refused at once with Retry-After and Connection: close; the two are queued and
    computed when they end."""
    app = create_app(Settings(max_jobs=1, max_waiting=1, max_uploads=2, upload_grace=30))
    release = anyio.Event()
    async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://m") as c:
        before = families((await c.get("/metrics")).text)
        statuses: list[int] = []

        async def slow_post():
            statuses.append((await post_held(c, release)).status_code)

        async with anyio.create_task_group() as group:
            group.start_soon(slow_post)
            group.start_soon(slow_post)
            with anyio.fail_after(5):
                while admission.job_gate(app).in_flight < 2:
                    await anyio.sleep(0.005)
            metrics = families((await c.get("/metrics")).text)
            started = time.perf_counter()
            refused = await post_held(c, release)
            waited = time.perf_counter() - started
            release.set()
        body = problem(refused, 503)
        assert "2 request bodies are arriving" in body["detail"]
        assert 1 <= int(refused.headers["retry-after"]) <= 60
        assert refused.headers["connection"] == "close"
        assert waited < 1.0  # refused, not queued
        assert statuses == [200, 200]
        # Gauges are per process: compare with the reading before (other tests' apps count).
        grown = sample(metrics, "meshflat_uploads_in_progress") - sample(
            before, "meshflat_uploads_in_progress"
        )
        assert grown == 2
        assert (await c.post("/v1/points", json=POINTS)).status_code == 200
        assert admission.job_gate(app).in_flight == 0


async def test_a_complete_request_computes_while_slow_uploads_arrive():
    app = create_app(Settings(max_jobs=1, max_waiting=4, max_uploads=8, upload_grace=30))
    release = anyio.Event()
    async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://m") as c:
        statuses: list[int] = []

        async def slow_post():
            statuses.append((await post_held(c, release)).status_code)

        async with anyio.create_task_group() as group:
            for _ in range(4):
                group.start_soon(slow_post)
            with anyio.fail_after(5):
                while admission.job_gate(app).in_flight < 4:
                    await anyio.sleep(0.005)
            for _ in range(3):
                assert (await c.post("/v1/points", json=POINTS)).status_code == 200
            release.set()
        assert statuses == [200] * 4


async def test_jobs_beyond_the_bound_are_refused_before_their_body_is_read(monkeypatch):
    """One job computing and one queued fill MESHFLAT_MAX_JOBS=1 + MESHFLAT_MAX_WAITING=1: a
    third request is refused as soon as its headers are in; its body is never asked for."""
    app = create_app(Settings(max_jobs=1, max_waiting=1))
    computing, finish = threading.Event(), threading.Event()

    def held_points(capability, body, content_type, job):
        computing.set()
        finish.wait(5)
        return Response(b"{}", media_type="application/json")

    monkeypatch.setattr(routes, "answer_json", held_points)
    read: list[bytes] = []

    async def watched_body():
        read.append(b"asked")
        yield orjson.dumps(POINTS)

    async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://m") as c:
        async with anyio.create_task_group() as group:
            for _ in range(2):
                group.start_soon(partial(c.post, "/v1/points", json=POINTS))
            with anyio.fail_after(5):
                while admission.job_gate(app).in_flight < 2 or not computing.is_set():
                    await anyio.sleep(0.005)
            refused = await c.post(
                "/v1/points", content=watched_body(), headers={"content-type": "application/json"}
            )
            finish.set()
        body = problem(refused, 503)
        assert "2 jobs are queued or computing" in body["detail"]
        assert refused.headers["connection"] == "close"
    assert admission.job_gate(app).in_flight == 0


async def test_a_body_slower_than_the_least_rate_is_a_408_after_the_grace():
    async with client_of(Settings(min_upload_rate=1000, upload_grace=0.2)) as c:

        async def trickle():
            yield b'{"points": '
            for _ in range(20):
                await anyio.sleep(0.1)
                yield b" "  # 10 bytes/s
            yield b"[]}"

        started = time.perf_counter()
        response = await c.post(
            "/v1/points", content=trickle(), headers={"content-type": "application/json"}
        )
        detail = problem(response, 408)["detail"]
        assert "slower than 1,000 bytes/s after 0.2 s" in detail
        assert "MESHFLAT_MIN_UPLOAD_RATE" in detail
        assert time.perf_counter() - started < 1.5


async def test_a_job_beyond_the_memory_budget_is_a_413_and_one_beyond_what_is_left_a_503():
    data = SAMPLES["fsaverage-head.ply"].path.read_bytes()
    files = {"mesh": ("head.ply", data)}
    async with client_of(Settings(memory_budget=16 * 2**20)) as c:
        body = problem(await c.post("/v1/flatten", files=files), 413)
        assert "MESHFLAT_MEMORY_BUDGET" in body["detail"] and "16 MiB" in body["detail"]
    gate = JobGate(max_jobs=2, max_waiting=0, memory_budget=1000)
    first, second = gate.admit(), gate.admit()
    first.charge(800)
    with pytest.raises(Problem) as busy:
        second.charge(300)
    assert busy.value.status == 503 and "memory budget" in busy.value.detail
    first.release()
    second.charge(300)  # given back when the first ended
    assert gate.memory.reserved == 300
    second.release()
    assert gate.memory.reserved == 0


async def test_a_body_that_does_not_arrive_in_time_is_a_408():
    async with client_of(Settings(request_timeout=0.2)) as c:

        async def stalled():
            yield b'{"points": '
            await anyio.sleep(2)
            yield b"[]}"

        response = await c.post(
            "/v1/points", content=stalled(), headers={"content-type": "application/json"}
        )
        assert "within the time limit of 0.2 s" in problem(response, 408)["detail"]


async def test_a_job_past_its_time_limit_is_a_504_and_stops_at_its_next_stage(monkeypatch):
    # 0.5 s: long enough for the job's thread to start on a loaded machine (a thread that
    # starts after the limit never computes, which another test pins).
    app = create_app(Settings(request_timeout=0.5))
    stages: list[str] = []
    finished = threading.Event()

    def slow_points(capability, body, content_type, job):
        timings = Timings(job.deadline)
        try:
            with timings.measure("parse"):
                stages.append("parse")
                time.sleep(3.0)  # well past the deadline
            with timings.measure("compute"):
                stages.append("compute")  # never reached
        finally:
            finished.set()

    monkeypatch.setattr(routes, "answer_json", slow_points)
    async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://m") as c:
        started = time.perf_counter()
        response = await c.post("/v1/points", json=POINTS)
        answered = time.perf_counter() - started
        body = problem(response, 504)
        assert "MESHFLAT_REQUEST_TIMEOUT" in body["detail"]
        assert answered < 2.5  # answered at the limit, long before the job ended
        # The job still holds its admission until its thread stops, at the next stage.
        assert admission.job_gate(app).in_flight == 1
        await anyio.to_thread.run_sync(finished.wait, 8)
        await anyio.sleep(0.05)
        assert stages == ["parse"]
        assert admission.job_gate(app).in_flight == 0


async def test_a_job_cancelled_before_its_thread_starts_leaves_no_admission_behind():
    """All worker threads busy: the job's time runs out while it waits for one, so its
    computation never starts; the admission must end all the same."""
    app = create_app(Settings(request_timeout=0.2))
    limiter = anyio.to_thread.current_default_thread_limiter()
    holders = [object() for _ in range(int(limiter.total_tokens))]
    for holder in holders:
        await limiter.acquire_on_behalf_of(holder)
    try:
        async with httpx.AsyncClient(
            transport=httpx.ASGITransport(app=app), base_url="http://m"
        ) as c:
            problem(await c.post("/v1/points", json=POINTS), 504)
            assert admission.job_gate(app).in_flight == 0
    finally:
        for holder in holders:
            limiter.release_on_behalf_of(holder)


def test_timings_refuse_a_stage_after_the_deadline():
    with pytest.raises(TimeLimit) as raised, Timings(Deadline.after(-1.0)).measure("compute"):
        pass
    assert raised.value.status == 504
    with Timings().measure("compute"):  # no deadline outside a job (the CLI)
        pass


def test_a_job_waiting_for_a_slot_past_its_deadline_does_not_start():
    gate = JobGate(max_jobs=1, max_waiting=1)
    first, second = gate.admit(), gate.admit()
    first.uploaded()
    second.uploaded()
    with pytest.raises(Problem) as busy:
        gate.admit()
    assert busy.value.status == 503
    computing, hold = threading.Event(), threading.Event()

    def occupy() -> None:
        computing.set()
        hold.wait(5)

    worker = threading.Thread(target=first.run, args=(occupy, Deadline.after(5)))
    worker.start()
    assert computing.wait(5)  # the first job has the only slot
    ran = []
    with pytest.raises(TimeLimit):
        second.run(lambda: ran.append(1), Deadline.after(0.1))
    assert ran == [] and gate.in_flight == 1
    hold.set()
    worker.join()
    assert gate.in_flight == 0


# -- request ids and logs ------------------------------------------------------------------


def test_warnings_and_other_libraries_log_json_lines(monkeypatch):
    """A Python warning (numpy's, a library's) and a third-party logger's record reach the log
    as JSON objects, like the service's own lines."""
    stream = io.StringIO()
    config = log_config()
    del config["handlers"]["stderr"]["stream"]  # sys.stderr when configured: the stream here
    # Only the parts under test: the service's and uvicorn's loggers stay as they are.
    config["loggers"] = {"py.warnings": config["loggers"]["py.warnings"]}
    monkeypatch.setattr(sys, "stderr", stream)
    logging.config.dictConfig(config)
    try:
        capture_warnings()
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.warn("field 'patient-7' has 1e400", RuntimeWarning, stacklevel=1)
        logging.getLogger("some.library").warning("a library's own warning")
    finally:
        capture_warnings(False)
        for name in ("py.warnings", "some.library", ""):
            logging.getLogger(name).handlers.clear()
    text = stream.getvalue()
    lines = [json.loads(line) for line in text.splitlines() if line.strip()]
    assert {line["logger"] for line in lines} == {"py.warnings", "some.library"}
    warned = next(line for line in lines if line["logger"] == "py.warnings")
    assert warned["category"] == "RuntimeWarning" and warned["where"].startswith("test_operations")
    assert "patient-7" not in text  # a warning's text never reaches the log


async def test_request_ids_are_accepted_returned_and_logged():
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(JsonFormatter())
    logger = logging.getLogger("meshflat")
    logger.addHandler(handler)
    try:
        async with client_of(Settings(api_keys=(KEY,))) as c:
            given = await c.get("/healthz", headers={"X-Request-ID": "planner-42.a"})
            assert given.headers["x-request-id"] == "planner-42.a"
            refused = await c.get("/v1/samples", headers={"X-Request-ID": "planner-43"})
            assert refused.status_code == 401 and refused.headers["x-request-id"] == "planner-43"
            for bad in ("has spaces", "x" * 129, "é"):
                response = await c.get("/healthz", headers={"X-Request-ID": bad.encode()})
                assert len(response.headers["x-request-id"]) == 32  # a new one
            fresh = (await c.get("/healthz")).headers["x-request-id"]
    finally:
        logger.removeHandler(handler)
    lines = [json.loads(line) for line in stream.getvalue().splitlines()]
    by_id = {line["request_id"]: line for line in lines if line["message"] == "request"}
    assert by_id["planner-42.a"]["route"] == "/healthz" and by_id["planner-42.a"]["status"] == 200
    assert by_id["planner-43"]["route"] == "/v1/samples" and by_id["planner-43"]["status"] == 401
    assert fresh in by_id
    assert {"time", "level", "logger", "duration_ms", "method"} <= set(by_id[fresh])


async def test_a_jobs_access_line_gives_what_it_was_charged(client):
    """``charged_bytes``: what ``make attack`` weighs a worker's growth against; at least
    the body and the reader's seven bytes per byte of it, and the mesh's computation."""
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(JsonFormatter())
    logging.getLogger("meshflat").addHandler(handler)
    try:
        response = await client.post(
            "/v1/flatten",
            files={"mesh": (HEAD, SAMPLES[HEAD].path.read_bytes())},
            headers={"X-Request-ID": "charged-1"},
        )
        assert response.status_code == 200
        assert (await client.get("/healthz", headers={"X-Request-ID": "free-1"})).is_success
    finally:
        logging.getLogger("meshflat").removeHandler(handler)
    lines = [json.loads(line) for line in stream.getvalue().splitlines()]
    by_id = {line["request_id"]: line for line in lines if line["message"] == "request"}
    body = int(response.request.headers["content-length"])
    assert by_id["charged-1"]["charged_bytes"] > 8 * body
    assert "charged_bytes" not in by_id["free-1"]  # not a job


async def test_logs_hold_nothing_of_the_mesh(client):
    secret = "patient-4d2b"
    obj = f"g {secret}\nv 0 0 1\nv 1 0 1\nv 0 1 1\nf 1 2 3\nf 1 2 9\n".encode()
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(JsonFormatter())
    logging.getLogger("meshflat").addHandler(handler)
    try:
        for data in (obj, obj.replace(b"f 1 2 9\n", b"")):
            response = await flatten(client, "x", {}, data=data, filename=f"{secret}.obj")
            assert response.status_code in (200, 422)
    finally:
        logging.getLogger("meshflat").removeHandler(handler)
    text = stream.getvalue()
    assert text.count('"message": "request"') == 2
    assert secret not in text


# -- metrics -------------------------------------------------------------------------------


def families(text: str) -> dict:
    """The exposition parsed by the Prometheus client's own parser: name -> family."""
    return {family.name: family for family in text_string_to_metric_families(text)}


def sample(parsed: dict, name: str, **labels) -> float:
    """The value of the sample ``name`` with ``labels`` (0 when there is none)."""
    family = parsed.get(name.removesuffix("_total")) or parsed.get(
        name.rpartition("_")[0]
    )  # histograms: name_count, name_bucket
    if family is None:
        return 0.0
    return sum(
        s.value
        for s in family.samples
        if s.name == name and all(s.labels.get(k) == v for k, v in labels.items())
    )


async def test_metrics_count_requests_sizes_and_refusals():
    async with client_of(Settings(api_keys=(KEY,), max_upload_bytes=200_000)) as c:
        before = families((await c.get("/metrics")).text)
        headers = {"X-API-Key": KEY}
        data = SAMPLES[HEAD].path.read_bytes()
        region = {"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}}
        for _ in range(2):
            response = await c.post(
                "/v1/flatten",
                files={"mesh": ("head.ply", data)},
                data={"params": json.dumps(region)},
                headers=headers,
            )
            assert response.status_code == 200, response.text
        await c.get("/v1/samples")  # 401
        await c.post("/v1/points", content=b"x" * 200_001, headers=headers)  # 413
        response = await c.get("/metrics")
        assert response.headers["content-type"].startswith("text/plain")
        after = families(response.text)

    def grew(name, **labels):
        return sample(after, name, **labels) - sample(before, name, **labels)

    flatten_ok = {"route": "/v1/flatten", "method": "POST", "status": "200"}
    assert grew("meshflat_requests_total", **flatten_ok) == 2
    assert grew("meshflat_request_duration_seconds_count", **flatten_ok) == 2
    assert grew("meshflat_requests_total", route="/v1/samples", status="401") == 1
    assert grew("meshflat_requests_total", route="/v1/points", status="413") == 1
    assert grew("meshflat_mesh_faces_count", format="ply") == 2
    assert grew("meshflat_mesh_faces_sum", format="ply") == 2 * len(load_sample(HEAD)[1])
    assert grew("meshflat_rejections_total", reason="unauthorized") == 1
    assert grew("meshflat_rejections_total", reason="body-too-large") == 1
    assert after["meshflat_jobs_in_flight"].type == "gauge"
    assert grew("meshflat_jobs_in_flight") == 0
    assert after["meshflat_request_duration_seconds"].type == "histogram"


class HandClock:
    """A monotonic clock that moves only when the test moves it."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_an_idle_worker_releases_memory_once_no_job_came_for_a_while():
    calls: list[int] = []
    clock = HandClock()
    gate = JobGate(
        max_jobs=1,
        max_waiting=1,
        on_idle=lambda: calls.append(1),
        idle_seconds=0.5,
        clock=clock,
        watch_idle=False,
    )
    gate.admit().release()
    clock.now += 0.3
    gate.admit().release()  # within the quiet time: the quiet spell starts again
    clock.now += 0.3
    assert not gate.idle_check()  # 0.6 s since the first, 0.3 s since the last departure
    clock.now += 0.3
    assert gate.idle_check() and not gate.idle_check()  # once a quiet spell
    assert calls == [1]
    held = gate.admit()  # nothing is due while a job is in flight
    clock.now += 60
    assert not gate.idle_check()
    assert calls == [1]
    held.release()
    clock.now += 0.6
    gate.idle_check()
    assert calls == [1, 1]


def test_the_gates_watcher_calls_on_idle_by_itself():
    called = threading.Event()
    gate = JobGate(max_jobs=1, max_waiting=1, on_idle=called.set, idle_seconds=0.01)
    gate.admit().release()
    assert called.wait(10)
