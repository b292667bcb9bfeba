"""``meshflat batch``: a data set of scans, each answered by the service's own code.

    meshflat batch MANIFEST.jsonl --out DIR [--allow-root DIR] [--processes N]
        [--shard-count N [--shard-index I]]

The manifest has one JSON object per line (blank lines are skipped), one scan each::

    {"mesh": "scans/p001.glb", "params": {"region": {...}}, "outputs": ["map.json", "map.png"]}

``mesh`` (relative to the manifest's folder, and inside it or an ``--allow-root``: a regular
file within the upload limit, :mod:`service.batchfiles`) and ``outputs`` (file names whose
extensions pick the forms, among those the command answers) are required; ``params`` are the
API's (default ``{}``), ``command`` a mesh route's command (default ``flatten``) and ``name``
the scan's folder under DIR (default: the mesh's file name without its extension). The whole
manifest is checked before anything runs (:mod:`service.batchmanifest`): a bad line stops the
batch, named by its number.

A scan's outputs are what the API answers, byte for byte (the same params model, reader,
operation and encoders: :meth:`service.capabilities.MeshCapability.render`), computed once and
written into ``DIR/NAME/``; then ``digest.json``, last and atomically: the SHA-256 of the
mesh's bytes with the command, the canonical params, the output names and meshflat's version,
and each output's size and SHA-256. A rerun skips a scan whose digest matches and whose outputs
are intact, so a batch that stopped goes on where it was. Nothing is written through a symbolic
link. A scan that fails gets ``error.json`` (the API's problem, and the line; a reader's
refusal by its kind and position only) and a log line; the others go on.

Scans run on N processes that start clean (from a fork server, not forked from the command:
nothing of its threads is inherited; BLAS on one thread each, as in the service); scans done
before are skipped first, without them. Each process is a pool of its own: one that dies costs
only the scan it was computing, computed once more on a fresh process, then failed. With
``--shard-count N`` a run takes the scans ``i`` with ``i % N == INDEX`` (counted from 0 in
manifest order), INDEX being ``--shard-index`` or ``JOB_COMPLETION_INDEX``, which Kubernetes
sets in each pod of an Indexed Job.

Logs are JSON lines on stderr: one per scan (name, line, outcome; a failure's status and
detail), then a summary. Nothing of a mesh goes to disk but the outputs asked for.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import logging
import math
import os
import sys
import time
from collections import Counter, deque
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from importlib.metadata import version
from multiprocessing import get_all_start_methods, get_context
from multiprocessing.context import BaseContext
from pathlib import Path

import orjson

from .batchfiles import (
    ScanFolder,
    content_free,
    partial_name,
    quoting_only,
    read_confined,
    words_of,
)
from .batchmanifest import DIGEST_FILE, ERROR_FILE, Scan, read_manifest, shard_of
from .batchmanifest import JOB_INDEX_VARIABLE as JOB_INDEX_VARIABLE  # the deploy's tests'
from .capabilities import MESH_COMMANDS
from .capabilities.context import Context
from .capabilities.inputs import Upload, parse_params
from .errors import UnreadableMesh
from .observability import JsonFormatter
from .problems import Problem, core_errors_as_problems, problem_body
from .progress import Progress
from .settings import Settings
from .timings import Timings

#: How many times a scan is computed whose process dies (killed, out of memory).
ATTEMPTS = 2
#: The exit status when scans failed (each logged, with its error.json); 2 is a bad manifest
#: or option, when nothing ran.
SCANS_FAILED = 1

logger = logging.getLogger("meshflat.batch")


@dataclass(frozen=True)
class Outcome:
    """What became of a scan: ``done``, ``skipped`` (done before, same inputs) or
    ``failed``, with the API's problem as its JSON has it (an exception object would not
    cross back from a worker process: ``Problem`` cannot be unpickled)."""

    scan: Scan
    status: str
    seconds: float
    problem: dict | None = None
    #: CPU seconds of a scan done (its process's), whatever else the machine runs.
    cpu_seconds: float | None = None


# -- one scan ------------------------------------------------------------------------------


def process(scan: Scan, out: Path, settings: Settings) -> Outcome:
    """Compute ``scan`` into ``out/NAME/`` unless its digest says it is done; a failure is
    recorded in its ``error.json`` (when the folder can be written) and returned, never
    raised."""
    started, path = time.perf_counter(), out / scan.name
    try:
        folder = ScanFolder(out, scan.name)
    except OSError as error:  # not writable, full, or a symbolic link at DIR/NAME
        why = "a symbolic link is there" if path.is_symlink() else error.strerror
        detail = f"cannot write in {str(path)!r}: {why}"
        return failed(scan, None, Problem(500, detail, "output-not-written"), started)
    with folder:
        try:
            return _process(scan, folder, settings, started)
        except OSError as error:  # the output folder: not writable, or full
            detail = f"cannot write in {str(path)!r}: {error.strerror}"
            return failed(scan, folder, Problem(500, detail, "output-not-written"), started)


def _process(scan: Scan, folder: ScanFolder, settings: Settings, started: float) -> Outcome:
    cpu = time.process_time()
    try:
        data = read_confined(scan.mesh, scan.roots, settings.max_upload_bytes)
    except Problem as problem:
        return failed(scan, folder, problem, started)
    digest = scan.digest(data)
    if _finished(folder, scan, digest):
        return Outcome(scan, "skipped", time.perf_counter() - started)
    _forget(folder, scan)
    try:
        written = _compute(scan, data, settings, folder)
    except Problem as problem:  # naming nothing the file holds that the line does not say
        given = words_of(scan.params) | {scan.command}
        return failed(scan, folder, quoting_only(problem, given), started)
    except OSError:
        raise  # writing the outputs (process says so)
    except Exception as error:  # a bug: this scan fails alone, named by the error's type only
        # (its message could quote the mesh).
        problem = Problem(500, f"internal error ({type(error).__name__})", "internal-error")
        return failed(scan, folder, problem, started)
    record = {"digest": digest, "meshflat": version("meshflat"), "outputs": written}
    folder.write_atomically(DIGEST_FILE, orjson.dumps(record, option=orjson.OPT_INDENT_2))
    seconds = time.perf_counter() - started
    return Outcome(scan, "done", seconds, cpu_seconds=time.process_time() - cpu)


def _compute(scan: Scan, data: bytes, settings: Settings, folder: ScanFolder) -> dict[str, dict]:
    """The outputs of one computation, each written as it is rendered (partial names until
    all are), with their sizes and SHA-256. A reader's refusal is told by its kind and
    position only (:func:`content_free`): its message may quote the file."""
    capability = MESH_COMMANDS[scan.command]
    timings = Timings()
    written = {}
    ctx = Context(settings)
    with core_errors_as_problems(capability.places):
        params = parse_params(capability.params, orjson.dumps(scan.params))
        try:
            given = capability.input_of(
                params, {capability.mesh.name: Upload(scan.mesh.name, data)}, ctx
            )
        except UnreadableMesh as error:
            raise content_free(error.error, error.part) from None
        with timings.measure("compute"):
            result = capability.operation(given, ctx)
        for name, output in scan.outputs:
            answer = capability.render(result, params, output, ctx, timings)
            folder.write_partial(name, answer)
            written[name] = {"bytes": len(answer), "sha256": hashlib.sha256(answer).hexdigest()}
    for name in written:
        folder.commit(name)
    return written


def _finished(folder: ScanFolder, scan: Scan, digest: str) -> bool:
    """Whether the folder's digest is ``digest`` and every output is as it recorded."""
    try:
        record = orjson.loads(folder.read(DIGEST_FILE))
    except (OSError, orjson.JSONDecodeError):
        return False
    if not isinstance(record, dict) or record.get("digest") != digest:
        return False
    recorded = record.get("outputs")
    return isinstance(recorded, dict) and all(
        _intact(folder, name, recorded.get(name)) for name, _ in scan.outputs
    )


def _intact(folder: ScanFolder, name: str, recorded) -> bool:
    try:
        data = folder.read(name)
    except OSError:
        return False
    return isinstance(recorded, dict) and recorded == {
        "bytes": len(data),
        "sha256": hashlib.sha256(data).hexdigest(),
    }


def _forget(folder: ScanFolder, scan: Scan) -> None:
    """Before a scan is computed: no record of an earlier run, and no output of other
    inputs left to pass for this one's."""
    for name in (DIGEST_FILE, ERROR_FILE, *(name for name, _ in scan.outputs)):
        folder.unlink(name)
        folder.unlink(partial_name(name))


def failed(scan: Scan, folder: ScanFolder | None, problem: Problem, started: float) -> Outcome:
    """The scan's failure, with its ``error.json`` in ``folder`` (None: it cannot be
    written; the log says why)."""
    answer = orjson.loads(problem_body(problem))
    record = {
        **answer,
        "scan": scan.name,
        "line": scan.line,
        "mesh": str(scan.mesh),
        "meshflat": version("meshflat"),
    }
    with contextlib.suppress(OSError):  # a folder that cannot be written: the log says why
        if folder is not None:
            for name, _ in scan.outputs:
                folder.unlink(partial_name(name))
            folder.write_atomically(ERROR_FILE, orjson.dumps(record, option=orjson.OPT_INDENT_2))
    return Outcome(scan, "failed", time.perf_counter() - started, answer)


# -- many scans ----------------------------------------------------------------------------


def outcomes(scans: list[Scan], out: Path, settings: Settings, processes: int) -> Iterator[Outcome]:
    """Each scan's outcome as it finishes: first those done before (checked here, so that a
    resumed batch starts no process for them), then the others on ``processes`` processes,
    or in this one when there is a single process or scan."""
    todo = []
    for scan in scans:
        started = time.perf_counter()
        if _done_before(scan, out, settings):
            yield Outcome(scan, "skipped", time.perf_counter() - started)
        else:
            todo.append(scan)
    if processes == 1 or len(todo) <= 1:
        for scan in todo:
            yield process(scan, out, settings)
        return
    yield from _on_processes(todo, out, settings, min(processes, len(todo)))


def _on_processes(todo: list[Scan], out: Path, settings: Settings, processes: int):
    """The scans on ``processes`` workers, each its own single-process pool, so that a
    worker's death (killed, out of memory) is the death of the one scan it was computing:
    that pool alone is replaced, the scan computed once more on a fresh process, and after
    :data:`ATTEMPTS` deaths written as failed with its ``error.json``; the others go on."""
    context = _fresh_processes()
    waiting, deaths = deque(todo), Counter()
    idle = [ProcessPoolExecutor(1, mp_context=context) for _ in range(processes)]
    running: dict[Future, tuple[ProcessPoolExecutor, Scan]] = {}
    try:
        while waiting or running:
            while waiting and idle:
                pool, scan = idle.pop(), waiting.popleft()
                running[pool.submit(process, scan, out, settings)] = (pool, scan)
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                pool, scan = running.pop(future)
                try:
                    outcome = future.result()
                except BrokenProcessPool:
                    pool.shutdown(wait=False)
                    idle.append(ProcessPoolExecutor(1, mp_context=context))
                    deaths[scan.line] += 1
                    if deaths[scan.line] < ATTEMPTS:
                        logger.warning(
                            "scan's process died: computing it again on a fresh one",
                            extra={"scan": scan.name, "line": scan.line},
                        )
                        waiting.appendleft(scan)
                        continue
                    outcome = _died(scan, out)
                else:
                    idle.append(pool)
                yield outcome
    finally:
        for pool in (*idle, *(pool for pool, _ in running.values())):
            pool.shutdown(wait=True, cancel_futures=True)


def _died(scan: Scan, out: Path) -> Outcome:
    """The failure of a scan whose process died each time, with its ``error.json``."""
    detail = (
        f"the process computing it died {ATTEMPTS} times (killed, or out of memory: "
        "MESHFLAT_MAX_VERTICES and MESHFLAT_MAX_FACES bound a mesh); rerun to retry"
    )
    problem = Problem(500, detail, "worker-died")
    try:
        folder = ScanFolder(out, scan.name)
    except OSError:
        return failed(scan, None, problem, time.perf_counter())
    with folder:
        return failed(scan, folder, problem, time.perf_counter())


def _done_before(scan: Scan, out: Path, settings: Settings) -> bool:
    try:
        data = read_confined(scan.mesh, scan.roots, settings.max_upload_bytes)
        with ScanFolder(out, scan.name, create=False) as folder:
            return _finished(folder, scan, scan.digest(data))
    except (Problem, OSError):
        return False  # its process says why


def _fresh_processes() -> BaseContext:
    """Worker processes that start clean, not forked from this one (whose threads and
    state they would inherit): forked from a fresh server process that has imported the
    service once (a few seconds), or else spawned, each importing it. BLAS runs on one
    thread in each (OPENBLAS_NUM_THREADS=1 from service/__init__.py is in their
    environment)."""
    if "forkserver" not in get_all_start_methods():
        return get_context("spawn")
    context = get_context("forkserver")
    context.set_forkserver_preload([__name__])
    return context


def available_cpus() -> int:
    """The CPUs this process may use: its affinity, capped by the cgroup's CPU quota (a
    container's CPU limit; the affinity still counts the node's cores)."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    quota = _cpu_quota()
    return max(1, min(cpus or 1, math.ceil(quota))) if quota else cpus or 1


def _cpu_quota() -> float | None:
    """CPUs' worth of time the cgroup may use (v2 ``cpu.max``, v1 ``cpu.cfs_quota_us``), or
    None without a limit."""
    with contextlib.suppress(OSError, ValueError):
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()[:2]
        return None if quota == "max" else int(quota) / int(period)
    with contextlib.suppress(OSError, ValueError):
        quota = int(Path("/sys/fs/cgroup/cpu/cpu.cfs_quota_us").read_text())
        period = int(Path("/sys/fs/cgroup/cpu/cpu.cfs_period_us").read_text())
        return quota / period if quota > 0 else None
    return None


def run_batch(args: argparse.Namespace) -> int:
    """``meshflat batch``: 0 when every scan is done (now or before), :data:`SCANS_FAILED`
    when any failed.

    Raises
    ------
    Problem
        The manifest or an option is wrong (nothing has run).
    """
    settings = Settings.from_env()
    allowed = tuple(Path(root) for root in args.allow_root or ())
    scans = read_manifest(Path(args.manifest), allowed)
    scans = shard_of(scans, args.shard_index, args.shard_count)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise Problem(422, f"cannot make {str(out)!r}: {error.strerror}", field="--out") from None
    progress = Progress([scan.name for scan in scans], args.progress or sys.stderr.isatty())
    counts = Counter({"done": 0, "skipped": 0, "failed": 0})
    started = time.perf_counter()
    progress.begin(f"{len(scans)} scans")
    with _logs_above(progress):
        for outcome in outcomes(scans, out, settings, args.processes or available_cpus()):
            counts[outcome.status] += 1
            _log(outcome)
            failed = f" ({counts['failed']} failed)" if counts["failed"] else ""
            progress.advance(f"{outcome.scan.name}{failed}")
        logger.info(
            "batch finished",
            extra={**counts, "seconds": round(time.perf_counter() - started, 3)},
        )
    return SCANS_FAILED if counts["failed"] else 0


def _log(outcome: Outcome) -> None:
    where = {"scan": outcome.scan.name, "line": outcome.scan.line}
    if outcome.status == "skipped":
        seconds = round(outcome.seconds, 3)
        logger.info("scan skipped: done before, same inputs", extra={**where, "seconds": seconds})
        return
    if outcome.problem is None:
        times = {"seconds": round(outcome.seconds, 3), "cpu_seconds": round(outcome.cpu_seconds, 3)}
        logger.info("scan done", extra={**where, **times})
        return
    problem = outcome.problem
    logger.error(
        "scan failed",
        extra={**where, **{key: problem.get(key) for key in ("status", "field", "detail")}},
    )


class _AboveTheBar(logging.StreamHandler):
    """JSON lines on stderr, written above the progress bar."""

    def __init__(self, progress: Progress) -> None:
        super().__init__(sys.stderr)
        self.progress = progress
        self.setFormatter(JsonFormatter())

    def emit(self, record: logging.LogRecord) -> None:
        with self.progress.above():
            super().emit(record)


@contextmanager
def _logs_above(progress: Progress) -> Iterator[None]:
    handler = _AboveTheBar(progress)
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
