"""A mesh sent once (POST /v1/meshes) and named by its SHA-256 afterwards: the digest, the
answers (the same bytes as with the mesh part, first and again from what was kept), the
refusals, the cache's bounds by bytes and by the memory budget, and nothing on disk."""

from __future__ import annotations

import hashlib
import json
import threading

import httpx
import numpy as np
import pytest

from service.capabilities import MESH_CAPABILITIES, locate
from service.capabilities.context import Context
from service.capabilities.inputs import MeshPart, parse_params
from service.capabilities.region import resolve
from service.capabilities.warnings import WarningCode
from service.errors import InvalidInput
from service.examples import icosahedron_obj, request_example
from service.meshcache import MeshCache, TooLarge, held_bytes
from service.meshio import Mesh
from service.samples import SAMPLES
from service.server.jobs import MemoryBudget
from service.settings import Settings

from .conftest import real_servers, started
from .test_api import SCALP, problem
from .test_measure import PARAMS as SCALP_MEASURE
from .test_measure import rectangle
from .test_operations import families, sample
from .test_privacy import watched_writes
from .test_serve import running

pytestmark = pytest.mark.anyio

HEAD = "fsaverage-head.ply"


def mesh_of(vertices: int, faces: int = 1) -> Mesh:
    """A mesh of ``vertices`` float64 rows and ``faces`` int64 rows: 24 bytes each."""
    return Mesh(np.zeros((vertices, 3)), np.zeros((faces, 3), dtype=np.int64))


async def hold(client, data: bytes, filename: str, params: dict | None = None):
    fields = {"params": json.dumps(params)} if params is not None else {}
    return await client.post("/v1/meshes", files={"mesh": (filename, data)}, data=fields)


async def post(client, endpoint: str, params: dict, files: dict | None = None):
    """A multipart form of ``params`` and ``files`` (a form even without files)."""
    parts = {"params": (None, json.dumps(params).encode(), "application/json"), **(files or {})}
    return await client.post(endpoint, files=parts)


# -- the cache -----------------------------------------------------------------------------


def test_the_least_recently_used_mesh_goes_first_once_the_bytes_are_over():
    cache = MeshCache(capacity=3 * 24 * 10)
    for name in "abc":
        cache.put(name, mesh_of(9))  # 10 rows of 24 bytes each
    assert cache.bytes == 720 and len(cache) == 3
    cache.mesh("a")  # now the most recently used
    cache.put("d", mesh_of(9))
    assert cache.mesh("b") is None
    assert all(cache.mesh(name) is not None for name in "acd")
    assert cache.bytes == 720


def test_a_mesh_beyond_the_capacity_is_too_large_and_zero_keeps_nothing():
    with pytest.raises(TooLarge):
        MeshCache(capacity=100).put("a", mesh_of(9))
    with pytest.raises(TooLarge):
        MeshCache(capacity=0).put("a", mesh_of(0, 0))


def test_what_is_computed_from_a_mesh_is_kept_counted_and_goes_with_it():
    cache = MeshCache(capacity=10_000)
    mesh, _ = cache.put("a", mesh_of(9))
    ctx = Context(meshes=cache)
    calls = []

    def step(ctx):
        calls.append(1)
        return np.ones(50)  # 400 bytes

    first = ctx.remembered(mesh, "step", step)
    assert ctx.remembered(mesh, "step", step) is first and len(calls) == 1
    assert cache.bytes == 240 + 400
    assert ctx.remembered(first, "next", lambda ctx: first[:10]) is not None  # a view: 0 more
    assert cache.bytes == 640
    cache.reclaim(1)  # the least recently used: the step's result, before its mesh
    assert cache.mesh("a") is mesh and cache.bytes == 240
    ctx.remembered(mesh, "step", step)
    assert len(calls) == 2
    cache.put("b", mesh_of(9_800 // 24))  # room only without "a" and its results
    assert cache.mesh("a") is None and len(cache) == 1


def test_a_step_on_what_the_cache_does_not_hold_is_computed_each_time():
    cache = MeshCache(capacity=10_000)
    ctx = Context(meshes=cache)
    loose = mesh_of(3)
    assert ctx.remembered(loose, "step", lambda ctx: 1) == 1
    assert ctx.remembered(loose, "step", lambda ctx: 2) == 2
    assert len(cache) == 0 and not ctx.holds(loose)


def test_a_kept_step_adds_its_warnings_again_each_time_it_is_used():
    cache = MeshCache(capacity=10_000)
    mesh, _ = cache.put("a", mesh_of(3))

    def warns(ctx):
        ctx.warn(WarningCode.REGION_PIECES, "region", "two pieces")
        return "value"

    for _ in range(2):
        ctx = Context(meshes=cache)
        assert ctx.remembered(mesh, "step", warns) == "value"
        assert [w.field for w in ctx.warnings] == ["region"]


def test_kept_arrays_are_read_only_and_hold_no_view_of_the_upload():
    body = bytearray(np.arange(9, dtype=np.float64).tobytes())
    viewing = Mesh(np.frombuffer(body, dtype=np.float64).reshape(3, 3), np.array([[0, 1, 2]]))
    mesh, size = MeshCache(capacity=1000).put("a", viewing)
    assert size == 72 + 24 and not mesh.vertices.flags.writeable
    assert mesh.vertices.base is None or isinstance(mesh.vertices.base, np.ndarray)
    with pytest.raises(ValueError):
        mesh.faces[0, 0] = 1


def test_held_bytes_count_a_block_of_memory_once():
    block = np.zeros(100)
    assert held_bytes({"a": block, "b": [block[:10], (block[5:],)]}) == 800


def test_the_cache_takes_its_bytes_from_the_jobs_budget_and_gives_way_to_them():
    budget = MemoryBudget(1000)
    cache = MeshCache(capacity=1000, budget=budget)
    budget.reclaim = cache.reclaim
    cache.put("a", mesh_of(19))  # 480 bytes
    assert budget.reserved == 480
    assert budget.take(600)  # a job: the cache lets go of the mesh
    assert cache.mesh("a") is None and budget.reserved == 600
    assert cache.put("b", mesh_of(19)) is None  # no room while the job holds it
    budget.give(600)
    assert cache.put("b", mesh_of(19)) is not None and budget.reserved == 480


def test_threads_keeping_using_and_reclaiming_at_once_leave_the_counts_exact():
    budget = MemoryBudget(40_000)
    cache = MeshCache(capacity=20_000, budget=budget)
    budget.reclaim = cache.reclaim
    errors = []

    def work(seed: int) -> None:
        rng = np.random.default_rng(seed)
        try:
            for _ in range(300):
                digest = str(rng.integers(8))
                held = cache.put(digest, mesh_of(int(rng.integers(1, 200))))
                if held is not None:
                    ctx = Context(meshes=cache)
                    step = ctx.remembered(held[0], "step", lambda ctx: np.ones(100))
                    ctx.remembered(step, "next", lambda ctx: np.ones(50))
                job = int(rng.integers(1, 30_000))
                if budget.take(job):  # a job, which may take the cache's room
                    budget.give(job)
        except Exception as error:  # reported below: a thread's error is lost otherwise
            errors.append(error)

    threads = [threading.Thread(target=work, args=(seed,)) for seed in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors
    assert cache.bytes == sum(unit.bytes for unit in cache._units.values()) <= 20_000
    assert budget.reserved == cache.bytes


# -- through the API -----------------------------------------------------------------------


async def test_a_mesh_sent_once_is_answered_by_the_sha256_of_its_bytes(client):
    data = SAMPLES[HEAD].path.read_bytes()
    first = await hold(client, data, HEAD)
    assert first.status_code == 201, first.text
    answer = first.json()
    assert answer["mesh_sha256"] == hashlib.sha256(data).hexdigest()
    assert answer["faces"] > 0 and answer["vertices"] > 0
    assert answer["bytes"] >= 24 * (answer["faces"] + answer["vertices"])
    again = await hold(client, data, "renamed.ply")
    assert again.status_code == 200 and again.json() == answer


async def test_the_kept_bytes_count_against_the_memory_budget():
    async with started(Settings()) as client:
        gate = client._transport.app.state.job_gate
        cache = client._transport.app.state.mesh_cache
        held = (await hold(client, SAMPLES[HEAD].path.read_bytes(), HEAD)).json()
        assert cache.bytes == held["bytes"] and gate.memory.reserved == cache.bytes
        digest = held["mesh_sha256"]
        assert (await post(client, "/v1/flatten", {"mesh_sha256": digest})).status_code == 200
        assert cache.bytes > held["bytes"]  # the region flattened is kept with it
        assert gate.memory.reserved == cache.bytes  # the job's own charges given back


@pytest.mark.parametrize("capability", MESH_CAPABILITIES, ids=lambda c: c.path)
async def test_every_mesh_route_answers_a_held_mesh_as_it_answers_the_mesh_part(client, capability):
    mesh = icosahedron_obj()
    params = request_example(capability.params)
    others = {
        part.name: ("icosahedron.obj", mesh)
        for part in capability.parts
        if isinstance(part, MeshPart) and part is not capability.mesh
    }
    sent = await post(
        client, capability.path, params, {capability.mesh.name: ("i.obj", mesh)} | others
    )
    assert sent.status_code == 200, sent.text
    digest = (await hold(client, mesh, "icosahedron.obj")).json()["mesh_sha256"]
    for _ in range(2):  # computed, then from what was kept
        held = await post(client, capability.path, {**params, "mesh_sha256": digest}, others)
        assert held.status_code == 200, held.text
        assert held.content == sent.content


#: The scalp as the locate benchmark clicks it, and the whole head (it warns of the seam).
SCALP_HEAD = SCALP[HEAD]
REQUESTS = [
    ("/v1/flatten", SCALP_HEAD),
    ("/v1/flatten", {}),
    ("/v1/validate", {"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}}),
    ("/v1/locate", {**SCALP_HEAD, "theta": [1.2, 1.5, 3.1], "phi": [0.3, -1.6, 0.0]}),
    ("/v1/locate", {**SCALP_HEAD, "theta": [1.5], "phi": [-1.6]}),
    ("/v1/locate", {**SCALP_HEAD, "theta": [1.5, 1.2], "phi": [-1.6, 0.4], "via": "map"}),
    ("/v1/measure", {**SCALP_MEASURE, "zones": [rectangle("crown", -1.0, 1.0, 0.9, 1.5)]}),
]


@pytest.mark.parametrize(("endpoint", "params"), REQUESTS)
async def test_a_held_scan_answers_byte_for_byte_what_its_mesh_part_does(client, endpoint, params):
    data = SAMPLES[HEAD].path.read_bytes()
    sent = await post(client, endpoint, params, {"mesh": (HEAD, data)})
    assert sent.status_code == 200, sent.text
    digest = (await hold(client, data, HEAD)).json()["mesh_sha256"]
    for _ in range(2):
        held = await post(client, endpoint, {**params, "mesh_sha256": digest})
        assert held.status_code == sent.status_code
        assert held.content == sent.content


async def test_a_repeated_click_on_a_held_mesh_selects_flattens_and_indexes_once(
    client, monkeypatch
):
    calls = []

    def counted(name, function):
        def call(*args, **kwargs):
            calls.append(name)
            return function(*args, **kwargs)

        return call

    monkeypatch.setattr(resolve, "select_region", counted("select", resolve.select_region))
    monkeypatch.setattr(resolve, "flatten_region", counted("flatten", resolve.flatten_region))
    monkeypatch.setattr(resolve, "_map_triangles", counted("map", resolve._map_triangles))
    monkeypatch.setattr(locate.LocateIndex, "build", counted("index", locate.LocateIndex.build))
    digest = (await hold(client, SAMPLES[HEAD].path.read_bytes(), HEAD)).json()["mesh_sha256"]
    click = {**SCALP_HEAD, "mesh_sha256": digest, "theta": [1.5], "phi": [-1.6]}
    for phi in (-1.6, -1.5, -1.4):  # the queries are not part of what is kept
        assert (await post(client, "/v1/locate", {**click, "phi": [phi]})).status_code == 200
    assert calls == ["select", "index"]
    for phi in (-1.6, -1.5):
        on_map = {**click, "phi": [phi], "via": "map"}
        assert (await post(client, "/v1/locate", on_map)).status_code == 200
    assert calls == ["select", "index", "flatten", "map"]  # the region resolved is shared
    moved = {**click, "sigma": 0.31}  # other params: another region
    assert (await post(client, "/v1/locate", moved)).status_code == 200
    assert calls[4:] == ["select", "index"]


async def test_a_digest_the_worker_does_not_hold_is_a_404_saying_to_send_the_mesh_again(client):
    unknown = hashlib.sha256(b"never sent").hexdigest()
    body = problem(await post(client, "/v1/flatten", {"mesh_sha256": unknown}), 404)
    assert body["field"] == "params.mesh_sha256" and unknown in body["detail"]
    assert "POST the mesh to /v1/meshes again" in body["detail"]


async def test_a_mesh_part_and_a_digest_together_are_refused(client):
    data = SAMPLES[HEAD].path.read_bytes()
    digest = (await hold(client, data, HEAD)).json()["mesh_sha256"]
    both = await post(client, "/v1/flatten", {"mesh_sha256": digest}, {"mesh": (HEAD, data)})
    assert "not both" in problem(both, 422, "params.mesh_sha256")["detail"]


async def test_neither_a_mesh_part_nor_a_digest_is_the_missing_part_refusal(client):
    problem(await post(client, "/v1/flatten", {}), 422, "mesh")


async def test_a_digest_must_be_64_hex_digits(client):
    problem(await post(client, "/v1/flatten", {"mesh_sha256": "abc"}), 422, "params.mesh_sha256")


async def test_sending_a_mesh_refuses_other_parts_and_unreadable_files(client):
    data = SAMPLES[HEAD].path.read_bytes()
    other = await client.post("/v1/meshes", files={"mesh": (HEAD, data), "mask": ("m.png", b"")})
    problem(other, 422, "mask")
    problem(await hold(client, b"not a mesh", "x.ply"), 422, "mesh")
    problem(await hold(client, data, "x.bin", {"format": "nope"}), 422, "params.format")
    assert (await hold(client, data, "x.bin", {"format": "ply"})).status_code in (200, 201)


async def test_a_worker_without_a_cache_refuses_to_keep_a_mesh():
    async with started(Settings(mesh_cache_bytes=0)) as client:
        answer = await hold(client, SAMPLES[HEAD].path.read_bytes(), HEAD)
        assert "MESHFLAT_MESH_CACHE_BYTES" in problem(answer, 413, "mesh")["detail"]


async def test_a_mesh_sent_after_others_that_fill_the_cache_evicts_the_oldest(client):
    meshes = [SAMPLES[name] for name in ("nefertiti-lowres.obj", HEAD)]
    first, second = [(await hold(client, m.path.read_bytes(), m.name)).json() for m in meshes]
    room = max(first["bytes"], second["bytes"]) + min(first["bytes"], second["bytes"]) // 2
    async with started(Settings(mesh_cache_bytes=room)) as small:
        for sample in meshes:
            assert (await hold(small, sample.path.read_bytes(), sample.name)).status_code == 201
        gone = await post(small, "/v1/flatten", {"mesh_sha256": first["mesh_sha256"]})
        problem(gone, 404, "params.mesh_sha256")
        kept = await post(small, "/v1/flatten", {"mesh_sha256": second["mesh_sha256"]})
        assert kept.status_code == 200


async def test_sending_and_using_a_held_mesh_opens_no_file_for_writing(client):
    warm, data = (SAMPLES[name].path.read_bytes() for name in ("nefertiti-lowres.obj", HEAD))
    locate = {**SCALP_HEAD, "theta": [1.5], "phi": [-1.6]}
    warmed = (await hold(client, warm, "warm.obj")).json()["mesh_sha256"]
    await post(client, "/v1/locate", {**locate, "mesh_sha256": warmed})  # imports done

    async def send_and_use():
        held = await hold(client, data, HEAD)
        assert held.status_code == 201
        for _ in range(2):  # computed and kept, then used
            params = {**locate, "mesh_sha256": held.json()["mesh_sha256"]}
            assert (await post(client, "/v1/locate", params)).status_code == 200

    assert await watched_writes(send_and_use) == []


@real_servers
def test_a_real_server_keeps_a_mesh_and_counts_it_in_its_metrics():
    data = SAMPLES[HEAD].path.read_bytes()
    with running() as server, httpx.Client(base_url=server.url, timeout=60) as client:
        held = client.post("/v1/meshes", files={"mesh": (HEAD, data)})
        assert held.status_code == 201, held.text
        click = {
            **SCALP_HEAD,
            "theta": [1.5],
            "phi": [-1.6],
            "mesh_sha256": held.json()["mesh_sha256"],
        }
        form = {"params": (None, json.dumps(click).encode(), "application/json")}
        answers = [client.post("/v1/locate", files=form) for _ in range(2)]
        assert [a.status_code for a in answers] == [200, 200] and answers[0].content == answers[
            1
        ].content
        metrics = families(client.get("/metrics").text)
        assert sample(metrics, "meshflat_mesh_cache_bytes") > held.json()["bytes"]
        assert sample(metrics, "meshflat_mesh_cache_steps_total", result="reused") >= 1
        assert sample(metrics, "meshflat_memory_reserved_bytes") == sample(
            metrics, "meshflat_mesh_cache_bytes"
        )


def test_the_command_line_refuses_a_digest():
    (flatten,) = [c for c in MESH_CAPABILITIES if c.path == "/v1/flatten"]
    params = parse_params(flatten.params, json.dumps({"mesh_sha256": "a" * 64}).encode())
    with pytest.raises(InvalidInput, match="POST /v1/meshes"):
        flatten.input_of(params, {}, Context(Settings()))


def test_the_cache_size_comes_from_the_environment_or_a_share_of_the_budget():
    assert Settings.from_env({"MESHFLAT_MESH_CACHE_BYTES": "0"}).mesh_cache_capacity == 0
    sized = Settings.from_env({"MESHFLAT_MESH_CACHE_BYTES": "1000"})
    assert sized.mesh_cache_capacity == 1000
    default = Settings(memory_budget=4_000_000_000)
    assert 0 < default.mesh_cache_capacity < default.memory_budget_bytes
    with pytest.raises(ValueError, match="MESHFLAT_MESH_CACHE_BYTES"):
        Settings.from_env({"MESHFLAT_MESH_CACHE_BYTES": "-1"})
