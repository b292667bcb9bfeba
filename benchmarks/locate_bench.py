"""Benchmark of ``POST /v1/locate`` and of the locate index (``make bench-locate``).

On the scalp of ``fsaverage-head.ply`` subdivided 3 and 5 times (99,675 and 1,594,796
faces), seen from its bounding-box centre with fixed parameters (centre, rotation and sigma
given, so no fit runs):

* one click end to end: one map point posted with the scalp as GLB to a real uvicorn on
  127.0.0.1 (a fresh ``meshflat serve`` per mesh), timed by curl, median of several runs
  after a warm-up; and the server's peak resident memory (VmHWM) before and after them;
* in-process, one thread: building the index, one query and 1M map points once it exists,
  one map point without an index (what the click runs), and, as the peer, Open3D's
  ``RaycastingScene`` (Embree; the sites-peers extra) on the same rays from the same
  centre, built and cast with ``nthreads=1``, timed alternately in the same process. The
  compiled walk (numba) is warmed up before any timed run.

Prints a Markdown table with the targets of issues 17 and 37; ``--write-docs`` records it in
docs/benchmarks.md. The hits of every run are checked against the points they came from.

    OMP_NUM_THREADS=1 python -m benchmarks.locate_bench [--runs 5] [--queries 1000000]
        [--write-docs]
"""

from __future__ import annotations

import argparse
import importlib.metadata
import shutil
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass

import numba
import numpy as np
import trimesh

from benchmarks.docs import footer, publish
from benchmarks.fit_bench import ladder_rung
from benchmarks.server import serving, status_bytes
from service.examples import MULTIPART, multipart_body
from service.server.allocator import keep_large_blocks
from transforms import Chart, Frame, LocateIndex, PoleCap, locate
from transforms.locate import DIRECT_QUERIES, SORTED_QUERIES

#: Targets from issue 17: one click end to end (ms) per rung, and queries per second.
CLICK_TARGET_MS = {3: 20.0, 5: 300.0}
QUERIES_PER_SECOND = 1e6
#: Targets from issue 37: one query once the index exists (µs); 1M queries no slower than
#: Open3D's RaycastingScene on one thread.
ONE_QUERY_TARGET_US = 30.0
#: Calls timed together for one query's time (a few µs each).
ONE_QUERY_CALLS = 200
SIGMA = 0.3
ROTATION = {"pole": [0, 0, -1], "up": [0, 1, 0]}


@dataclass(frozen=True)
class Scalp:
    subdivisions: int
    vertices: np.ndarray
    faces: np.ndarray
    frame: Frame
    chart: Chart

    @classmethod
    def of(cls, subdivisions: int) -> Scalp:
        vertices, faces = ladder_rung(subdivisions)
        centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
        frame = Frame.from_pole_up(ROTATION["pole"], ROTATION["up"], centre)
        return cls(subdivisions, vertices, faces, frame, Chart.distorted(PoleCap.from_sigma(SIGMA)))

    def map_points(self, count: int, seed: int = 0):
        """``count`` random points of the surface: their faces, and their map coordinates
        and local directions."""
        rng = np.random.default_rng(seed)
        picked = rng.integers(0, len(self.faces), count)
        weights = rng.dirichlet([1.0, 1.0, 1.0], count)
        points = np.einsum("kc,kcj->kj", weights, self.vertices[self.faces[picked]])
        theta, phi, _ = self.chart.forward(self.frame.to_local(points))
        return picked, theta, phi, self.chart.inverse(theta, phi, 1.0)

    def click(self) -> tuple[int, dict, bytes]:
        """One click's request: the face of its point, the params (the fixed frame and the
        point's map coordinates) and the scalp as GLB."""
        picked, theta, phi, _ = self.map_points(1, seed=1)
        params = {
            "center": self.frame.center.tolist(),
            "rotation": ROTATION,
            "sigma": SIGMA,
            "theta": theta.tolist(),
            "phi": phi.tolist(),
        }
        glb = trimesh.Trimesh(self.vertices, self.faces, process=False).export(file_type="glb")
        return int(picked[0]), params, glb


def progress(text: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


# -- one click through a real server ---------------------------------------------------------


def curl_post(url: str, body: bytes) -> tuple[float, bytes, str]:
    """curl's own total time for one POST, the answer and its Server-Timing header."""
    done = subprocess.run(
        ["curl", "--silent", "--show-error", "--fail", "--dump-header", "/dev/stderr",
         "--write-out", "\n%{time_total}", "--header", "Expect:",
         "--header", f"Content-Type: {MULTIPART}", "--data-binary", "@-", url],
        input=body, capture_output=True, check=True,
    )  # fmt: skip
    answer, seconds = done.stdout.rsplit(b"\n", 1)
    timing = next(
        (line.split(":", 1)[1].strip() for line in done.stderr.decode().splitlines()
         if line.lower().startswith("server-timing:")),
        "",
    )  # fmt: skip
    return float(seconds), answer, timing


def click(scalp: Scalp, runs: int) -> dict:
    """One map point posted with the scalp as GLB, ``runs`` times after a warm-up, to a fresh
    server: curl's times, the last Server-Timing, the server's VmHWM before and after."""
    picked, params, glb = scalp.click()
    body = multipart_body(params, "scalp.glb", glb)
    with serving({}, own_limits=True) as served:
        idle = status_bytes("VmHWM", served.process.pid) / 2**20
        seconds, timing = [], ""
        for _ in range(runs + 1):
            took, answer, timing = curl_post(f"{served.url}/v1/locate", body)
            seconds.append(took)
            assert f'"face":{picked},'.encode() in answer, answer[:300]
        peak = status_bytes("VmHWM", served.process.pid) / 2**20
    return dict(seconds=seconds[1:], timing=timing, idle=idle, peak=peak, upload=len(glb))


# -- in-process --------------------------------------------------------------------------


def timed(work, runs: int, clock=time.perf_counter) -> list[float]:
    times = []
    for _ in range(runs):
        start = clock()
        work()
        times.append(clock() - start)
    return times


def in_process(scalp: Scalp, queries: int, runs: int) -> dict:
    local = scalp.frame.to_local(scalp.vertices)
    picked, _, _, directions = scalp.map_points(queries)
    index = LocateIndex.build(local, scalp.faces)
    index.query(directions[: SORTED_QUERIES + 1])  # the compiled walk's warm-up
    build = timed(lambda: LocateIndex.build(local, scalp.faces), runs)
    peer = Open3D(local, scalp.faces)
    one = directions[:1]
    ours, ours_cpu, theirs, one_ours, one_theirs, one_cpu = [], [], [], [], [], []
    for _ in range(runs):  # alternately, so that both see the same machine
        ours += timed(lambda: check(index.query(directions).faces, picked), 1)
        ours_cpu += timed(lambda: index.query(directions), 1, time.process_time)
        theirs += timed(lambda: check(peer.cast(directions), picked, peer=True), 1)
        one_ours.append(per_call(lambda: index.query(one)))
        one_cpu.append(per_call(lambda: index.query(one), time.process_time))
        one_theirs.append(per_call(lambda: peer.cast(one)))
    check(index.query(one).faces, picked[:1])
    check(peer.cast(one), picked[:1])
    few = directions[:DIRECT_QUERIES]
    click_ours = timed(lambda: check(locate(local, scalp.faces, one).faces, picked[:1]), runs)
    click_peer = timed(lambda: check(Open3D(local, scalp.faces).cast(one), picked[:1]), runs)
    few_ours = timed(lambda: check(locate(local, scalp.faces, few).faces, picked[: len(few)]), runs)
    arrays = (index.levels, index.cell_start, index.entry_face, index.entry_box)
    return dict(
        build=build,
        ours=ours,
        ours_cpu=ours_cpu,
        peer=theirs,
        one_ours=one_ours,
        one_cpu=one_cpu,
        one_peer=one_theirs,
        click_ours=click_ours,
        click_peer=click_peer,
        few_ours=few_ours,
        entries=len(index.entry_face),
        cells=len(index.cell_start) - 1,
        index_bytes=sum(array.nbytes for array in arrays),
    )


def per_call(work, clock=time.perf_counter) -> float:
    """Seconds per call of ``work``, over ``ONE_QUERY_CALLS`` calls."""
    start = clock()
    for _ in range(ONE_QUERY_CALLS):
        work()
    return (clock() - start) / ONE_QUERY_CALLS


def check(faces: np.ndarray, picked: np.ndarray, peer: bool = False) -> None:
    """The faces hit are the faces the points came from: all of them for meshflat; for the
    peer, which casts in float32, all but one in 10,000 (rays through an edge or a vertex)."""
    found = (faces == picked).mean()
    assert found == 1.0 or (peer and found >= 0.9999), f"{found:.6f} of the faces found"


# -- the peer: Open3D's RaycastingScene --------------------------------------------------


class Open3D:
    """Open3D's ``RaycastingScene`` (Embree) over the region, on one thread: rays from the
    centre (the local origin) in float32, as it takes them."""

    def __init__(self, vertices_local: np.ndarray, faces: np.ndarray) -> None:
        import open3d as o3d

        self.o3d = o3d
        self.scene = o3d.t.geometry.RaycastingScene(nthreads=1)
        self.scene.add_triangles(
            o3d.core.Tensor(vertices_local.astype(np.float32)),
            o3d.core.Tensor(faces.astype(np.uint32)),
        )

    def cast(self, directions: np.ndarray) -> np.ndarray:
        """The face each ray meets first, -1 for none."""
        rays = np.zeros((len(directions), 6), dtype=np.float32)
        rays[:, 3:] = directions
        answer = self.scene.cast_rays(self.o3d.core.Tensor(rays), nthreads=1)
        faces = answer["primitive_ids"].numpy().astype(np.int64)
        faces[faces == self.o3d.t.geometry.RaycastingScene.INVALID_ID] = -1
        return faces


# -- the report --------------------------------------------------------------------------


def ms(values: list[float]) -> float:
    return statistics.median(values) * 1e3


def rows_of(scalp: Scalp, served: dict, local: dict, queries: int) -> list[str]:
    title = f"scalp, {len(scalp.faces):,} faces"
    target = CLICK_TARGET_MS[scalp.subdivisions]
    click_ms = ms(served["seconds"])
    rate = queries / statistics.median(local["ours"])
    peer_rate = queries / statistics.median(local["peer"])
    one_us, one_cpu_us, one_peer_us = (
        statistics.median(local[key]) * 1e6 for key in ("one_ours", "one_cpu", "one_peer")
    )
    many_ms, many_peer_ms = ms(local["ours"]), ms(local["peer"])
    per_face = local["index_bytes"] / len(scalp.faces)

    def row(measure, ours, peer="-", goal="-", met="-"):
        return f"| {title} | {measure} | {ours} | {peer} | {goal} | {met} |"

    def yes(met: bool) -> str:
        return "yes" if met else "no"

    return [
        row(
            f"one click end to end, curl (ms; GLB {served['upload'] / 1e6:.1f} MB)",
            f"{click_ms:,.0f}",
            "-",
            f"<= {target:.0f} ms",
            yes(click_ms <= target),
        ),
        row("server timing of the last click (ms)", served["timing"].replace(", ", "; ")),
        row(
            "server peak RSS, fresh process (VmHWM, MiB): ready / after the clicks",
            f"{served['idle']:,.0f} / {served['peak']:,.0f}",
        ),
        row(
            "one click in-process, locate only, no index (ms; Open3D: scene built and cast)",
            f"{ms(local['click_ours']):,.1f}",
            f"{ms(local['click_peer']):,.1f}",
        ),
        row(
            f"{DIRECT_QUERIES} map points without the index, against building it (ms)",
            f"{ms(local['few_ours']):,.0f} against {ms(local['build']):,.0f}",
        ),
        row(
            f"index size: {local['entries'] / len(scalp.faces):.2f} entries and "
            f"{local['cells'] / len(scalp.faces):.2f} cells per face (bytes per face)",
            f"{per_face:.0f}",
        ),
        row(
            "one query once the index exists (µs; on CPU time alone)",
            f"{one_us:,.1f} ({one_cpu_us:,.1f})",
            f"{one_peer_us:,.1f}",
            f"<= {ONE_QUERY_TARGET_US:.0f} µs",
            yes(one_us <= ONE_QUERY_TARGET_US),
        ),
        row(
            f"{queries:,} map points once the index exists (ms)",
            f"{many_ms:,.0f}",
            f"{many_peer_ms:,.0f}",
            "<= Open3D",
            yes(many_ms <= many_peer_ms),
        ),
        row(
            "queries per second once the index exists (on CPU time alone)",
            f"{rate / 1e6:.2f} M ({queries / statistics.median(local['ours_cpu']) / 1e6:.2f} M)",
            f"{peer_rate / 1e6:.2f} M",
            f">= {QUERIES_PER_SECOND / 1e6:.0f} M",
            yes(rate >= QUERIES_PER_SECOND),
        ),
    ]


def measure(runs: int, queries: int) -> str:
    open3d = importlib.metadata.version("open3d")
    lines = [
        f"Scalp of `fsaverage-head.ply` subdivided 3 and 5 times, centre, rotation and sigma "
        f"({SIGMA}) given. End to end: one map point and the mesh as GLB posted by curl to a "
        f"fresh `meshflat serve` (one worker) on 127.0.0.1, median of {runs} runs after a "
        "warm-up. In-process: one thread (BLAS and OpenMP too), median of "
        f"{runs} runs; the peer is Open3D {open3d}'s `RaycastingScene` (Embree, float32) "
        "built and cast with `nthreads=1`, on the same rays from the same centre, timed "
        "alternately in the same process (one query: the mean of "
        f"{ONE_QUERY_CALLS} calls per run); meshflat's compiled walk warmed up first.",
        "",
        "| region | measure | meshflat | Open3D `RaycastingScene` | target | met |",
        "|---|---|---:|---:|---|---|",
    ]
    for subdivisions in (3, 5):
        progress(f"scalp subdivided {subdivisions} times")
        scalp = Scalp.of(subdivisions)
        progress("end to end")
        served = click(scalp, runs)
        progress("in-process")
        local = in_process(scalp, queries, runs)
        lines += rows_of(scalp, served, local, queries)
    lines += [
        "",
        footer(f"numpy {np.__version__}", f"numba {numba.__version__}", f"Open3D {open3d}"),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5, help="timed runs per measure (median)")
    parser.add_argument("--queries", type=int, default=1_000_000, help="map points at once")
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    if shutil.which("curl") is None:
        raise SystemExit("the benchmark needs curl (apt-get install -y curl)")
    keep_large_blocks()
    report = measure(args.runs, args.queries)
    publish("locate-bench", "Locate: a click on the map", report, args.write_docs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
