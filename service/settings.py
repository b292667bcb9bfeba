"""Settings from environment variables (``MESHFLAT_*``), read once when the app is built.

Every setting of the service and of ``meshflat serve`` is an environment variable: a
container is configured without a file or a command-line flag.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path

from .images import MAX_PIXELS
from .meshio import Limits


@dataclass(frozen=True)
class Settings:
    """Limits, access and tuning of the service.

    Attributes
    ----------
    max_upload_bytes : MESHFLAT_MAX_UPLOAD_BYTES, largest request body (and decoded glTF
        buffer); beyond it the answer is 413, decided while the body streams in
    max_vertices, max_faces : MESHFLAT_MAX_VERTICES, MESHFLAT_MAX_FACES, per mesh
    max_points : MESHFLAT_MAX_POINTS, per /v1/points or /v1/locate request
    max_drawn_points : MESHFLAT_MAX_DRAWN_POINTS, the points of all the zones' rings and the
        curves of a /v1/measure request, and of the zones of a /v1/sites, /v1/plan or
        /v1/register request (an outline a surgeon draws has hundreds)
    max_curve_crossings : MESHFLAT_MAX_CURVE_CROSSINGS, the triangle edges all the curves of
        a /v1/measure request may cross (counted from their lengths on the map before they
        are lifted: a point of the answer and under 1 KB of memory each)
    max_sites : MESHFLAT_MAX_SITES, sites one /v1/sites request may place
    max_image_pixels : MESHFLAT_MAX_IMAGE_PIXELS, pixels of a PNG part (a mask, a density
        map, an image), from its header before a pixel is decoded
    threads : MESHFLAT_THREADS, threads one request's computation may use
    max_jobs : MESHFLAT_MAX_JOBS, jobs computed at once per process
    max_waiting : MESHFLAT_MAX_WAITING, jobs queued for a slot beyond those (their bodies in);
        a request that finds ``max_jobs + max_waiting`` jobs is refused as soon as its headers
        are in, with a 503 (service.server.jobs)
    max_uploads : MESHFLAT_MAX_UPLOADS, request bodies arriving at once per process (they hold
        no compute slot)
    memory_budget : MESHFLAT_MEMORY_BUDGET, bytes per process for its jobs' bodies, readers
        and computations and its mesh cache; 0 (the default): :func:`memory_budget_of` the
        container's limit
    mesh_cache_bytes : MESHFLAT_MESH_CACHE_BYTES, the most the process's cache of meshes sent
        once (POST /v1/meshes: the meshes and what is computed from them) holds, within the
        memory budget (a job's charge that finds no room empties it, least recently used
        first); 0: no cache; unset: :data:`MESH_CACHE_SHARE` of the memory budget
    min_upload_rate, upload_grace : MESHFLAT_MIN_UPLOAD_RATE bytes/s, MESHFLAT_UPLOAD_GRACE
        seconds: after the grace, a body must have arrived at that mean rate, or a 408
    header_timeout : MESHFLAT_HEADER_TIMEOUT, seconds for a request's headers to arrive on a
        connection (a new one, or a kept-alive one once it has started a request); 0: no
        limit (behind an ingress that keeps one)
    lingering_close : MESHFLAT_LINGERING_CLOSE, the longest a connection answered before its
        body was read (a refusal, a 401) is read and dropped before it is closed, seconds; 0:
        closed at once (behind an ingress that does this itself)
    keep_alive_timeout : MESHFLAT_KEEP_ALIVE_TIMEOUT, seconds an idle connection stays open
    request_timeout : MESHFLAT_REQUEST_TIMEOUT, seconds a job may take from its first byte to
        its answer (a 408 while the body is still arriving, a 504 after)
    api_keys : MESHFLAT_API_KEYS, comma-separated keys; with any, every ``/v1`` route needs one
    api_keys_file : MESHFLAT_API_KEYS_FILE, a file of keys, one per line (a mounted secret)
    cors_origins : MESHFLAT_CORS_ORIGINS, comma-separated origins a browser may call from
    host, port, workers : MESHFLAT_HOST, MESHFLAT_PORT, MESHFLAT_WORKERS, for ``meshflat serve``
    """

    # The reader's limits and these are one set of numbers: the defaults come from Limits.
    max_upload_bytes: int = Limits.max_bytes
    max_vertices: int = Limits.max_vertices
    max_faces: int = Limits.max_faces
    max_points: int = 5_000_000
    max_drawn_points: int = 100_000
    max_curve_crossings: int = 250_000
    max_sites: int = 1_000_000
    max_image_pixels: int = MAX_PIXELS
    threads: int = 1
    max_jobs: int = 2
    max_waiting: int = 1
    max_uploads: int = 256
    memory_budget: int = 0
    mesh_cache_bytes: int = -1  # unset: a share of the budget (mesh_cache_capacity)
    min_upload_rate: int = 64 * 1024
    upload_grace: float = 2.0
    header_timeout: float = 10.0
    lingering_close: float = 2.0
    keep_alive_timeout: float = 5.0
    request_timeout: float = 60.0
    api_keys: tuple[str, ...] = field(default=(), repr=False)
    api_keys_file: str = ""
    cors_origins: tuple[str, ...] = ()
    host: str = "127.0.0.1"
    port: int = 8000
    workers: int = 1

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None) -> Settings:
        """Read ``MESHFLAT_<FIELD>`` for every field; unset ones keep their defaults.

        Raises
        ------
        ValueError
            A number that is not positive, or a key file that cannot be read (the service
            refuses to start, naming the variable).
        """
        environ = os.environ if environ is None else environ
        values = {}
        for item in fields(cls):
            name = f"MESHFLAT_{item.name.upper()}"
            if name in environ:
                values[item.name] = _parse(name, environ[name].strip(), item.default)
        settings = cls(**values)
        if settings.api_keys_file:
            try:
                text = Path(settings.api_keys_file).read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as error:
                raise ValueError(
                    f"MESHFLAT_API_KEYS_FILE: cannot read {settings.api_keys_file!r} "
                    f"({type(error).__name__})"
                ) from None
            keys = tuple(line.strip() for line in text.splitlines() if line.strip())
            settings = cls(**{**values, "api_keys": settings.api_keys + keys})
        return settings

    @property
    def memory_budget_bytes(self) -> int:
        """MESHFLAT_MEMORY_BUDGET, or the share of the container's memory for one worker."""
        return self.memory_budget or memory_budget_of(container_memory(), self.workers)

    @property
    def mesh_cache_capacity(self) -> int:
        """MESHFLAT_MESH_CACHE_BYTES, or :data:`MESH_CACHE_SHARE` of the memory budget."""
        if self.mesh_cache_bytes >= 0:
            return self.mesh_cache_bytes
        return int(self.memory_budget_bytes * MESH_CACHE_SHARE)

    @property
    def limits(self) -> Limits:
        return Limits(
            max_vertices=self.max_vertices,
            max_faces=self.max_faces,
            max_bytes=self.max_upload_bytes,
        )


MiB = 2**20
#: What a worker process holds before any job (interpreter, numpy, scipy, the app, a warm
#: heap): measured as the RSS of an idle worker after the start-up self-check, rounded up.
WORKER_BASELINE_BYTES = 320 * MiB
#: The share of a container's memory given to the workers' budgets; the rest is headroom
#: for what the estimates do not see (allocator fragmentation, thread stacks).
BUDGET_SHARE = 0.8
#: The share of a worker's memory budget its mesh cache may hold unless
#: MESHFLAT_MESH_CACHE_BYTES says: a 1.6M-face scalp with its region, map and locate index
#: takes 411 MiB (make bench-cache); the jobs take back what they need (it gives way).
MESH_CACHE_SHARE = 0.25


def memory_budget_of(container_bytes: int, workers: int) -> int:
    """One worker's budget in a container of ``container_bytes``: its share after every
    worker's baseline (at least 128 MiB, room for a small scan's job)."""
    usable = container_bytes * BUDGET_SHARE - workers * WORKER_BASELINE_BYTES
    return max(128 * MiB, int(usable / workers))


def container_memory_for(budget: int, workers: int) -> int:
    """The container memory limit at which each of ``workers`` gets ``budget``: the inverse
    of :func:`memory_budget_of` (the manifests' limit is this, see tests/test_deploy.py)."""
    return math.ceil((budget * workers + workers * WORKER_BASELINE_BYTES) / BUDGET_SHARE)


def container_memory() -> int:
    """The cgroup's memory limit (v2 ``memory.max`` or v1 ``memory.limit_in_bytes``), or the
    machine's memory when there is none."""
    physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            return min(int(text), physical)  # v1 says "no limit" as a huge number
    return physical


def _parse(name: str, text: str, default: object) -> object:
    """``text`` as the type of the field's ``default``."""
    if isinstance(default, tuple):
        return tuple(item.strip() for item in text.split(",") if item.strip())
    if isinstance(default, str):
        return text
    kind = type(default)
    try:
        value = kind(text)
    except ValueError:
        value = None
    zero_allowed = name in _MAY_BE_ZERO
    valid = (
        value is not None and math.isfinite(value) and (value > 0 or (zero_allowed and value == 0))
    )
    if not valid:
        noun = "an integer" if kind is int else "a number"
        bound = "0 or more" if zero_allowed else "above 0"
        raise ValueError(f"{name} must be {noun} {bound}, got {text!r}")
    return value


#: Settings for which 0 makes sense: no queue (a job beyond MESHFLAT_MAX_JOBS is refused);
#: the budget from the container; no mesh cache; no header timer and no lingering close (an
#: ingress in front does both).
_MAY_BE_ZERO = frozenset(
    {
        "MESHFLAT_MAX_WAITING",
        "MESHFLAT_MEMORY_BUDGET",
        "MESHFLAT_MESH_CACHE_BYTES",
        "MESHFLAT_HEADER_TIMEOUT",
        "MESHFLAT_LINGERING_CLOSE",
    }
)
