"""Benchmark of ``POST /v1/locate`` and of the locate index (``make bench-locate``).

On the scalp of ``fsaverage-head.ply`` subdivided 3 and 5 times (99,675 and 1,594,796
faces), seen from its bounding-box centre with fixed parameters (centre, rotation and sigma
given, so no fit runs):

* one click end to end: one map point posted with the scalp as GLB to a real uvicorn on
  127.0.0.1 (a fresh ``meshflat serve`` per mesh), timed by curl, median of several runs
  after a warm-up; and the server's peak resident memory (VmHWM) before and after them;
* in-process, one thread: building the index, 1M map points once it exists (queries per
  second), one map point without an index (what the click runs), and, as the peer, the
  k-d tree version this index replaced (its copy below, timed alternately in the same
  process: it builds its trees on every call, so its time for 1M points includes them).

Prints a Markdown table with the targets of issue 17; ``--write-docs`` records it in
docs/benchmarks.md. The hits of every run are checked against the points they came from.

    python -m benchmarks.locate_bench [--runs 5] [--queries 1000000] [--write-docs]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from benchmarks.docs import footer, publish
from benchmarks.fit_bench import ladder_rung
from benchmarks.server import serving, status_bytes
from service.examples import MULTIPART, multipart_body
from service.server.allocator import keep_large_blocks
from transforms import Chart, Frame, LocateIndex, PoleCap, locate
from transforms.arrays import as_faces, as_points, unit_rows
from transforms.locate import DIRECT_QUERIES

#: Targets from issue 17: one click end to end (ms) per rung, and queries per second.
CLICK_TARGET_MS = {3: 20.0, 5: 300.0}
QUERIES_PER_SECOND = 1e6
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
    picked, theta, phi, _ = scalp.map_points(1, seed=1)
    params = {
        "center": scalp.frame.center.tolist(),
        "rotation": ROTATION,
        "sigma": SIGMA,
        "theta": theta.tolist(),
        "phi": phi.tolist(),
    }
    glb = trimesh.Trimesh(scalp.vertices, scalp.faces, process=False).export(file_type="glb")
    body = multipart_body(params, "scalp.glb", glb)
    with serving({}, own_limits=True) as served:
        idle = status_bytes("VmHWM", served.process.pid) / 2**20
        seconds, timing = [], ""
        for _ in range(runs + 1):
            took, answer, timing = curl_post(f"{served.url}/v1/locate", body)
            seconds.append(took)
            assert f'"face":{int(picked[0])},'.encode() in answer, answer[:300]
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
    build = timed(lambda: LocateIndex.build(local, scalp.faces), runs)
    ours, ours_cpu, peer = [], [], []
    for _ in range(runs):  # alternately, so that both see the same machine
        ours += timed(lambda: check(index.query(directions).faces, picked), 1)
        ours_cpu += timed(lambda: index.query(directions), 1, time.process_time)
        peer += timed(lambda: check(kdtree_locate(local, scalp.faces, directions), picked), 1)
    one, few = directions[:1], directions[:DIRECT_QUERIES]
    click_ours = timed(lambda: check(locate(local, scalp.faces, one).faces, picked[:1]), runs)
    click_peer = timed(lambda: check(kdtree_locate(local, scalp.faces, one), picked[:1]), runs)
    few_ours = timed(lambda: check(locate(local, scalp.faces, few).faces, picked[: len(few)]), runs)
    arrays = (index.levels, index.cell_start, index.entry_face, index.entry_box)
    return dict(
        build=build,
        ours=ours,
        ours_cpu=ours_cpu,
        peer=peer,
        click_ours=click_ours,
        click_peer=click_peer,
        few_ours=few_ours,
        entries=len(index.entry_face),
        cells=len(index.cell_start) - 1,
        index_bytes=sum(array.nbytes for array in arrays),
    )


def check(faces: np.ndarray, picked: np.ndarray) -> None:
    assert (faces == picked).all(), "locate did not find the faces the points came from"


# -- the peer: the k-d tree version this index replaced (its code as it was) -----------------

_FIRST_NEIGHBOURS = 8
_CHUNK = 65536
_INSIDE = -1e-12


def kdtree_locate(vertices_local, faces, directions) -> np.ndarray:
    """The faces the rays meet first, by k-d trees over the triangles' direction caps, one
    tree per size class, built on every call."""
    points = as_points(vertices_local, "vertices")
    faces = as_faces(faces, len(points))
    rays, _ = unit_rows(as_points(directions, "directions"))
    corner_units, _ = unit_rows(points)
    k = len(rays)
    hit_face = np.full(k, -1, dtype=np.int64)
    hit_depth = np.full(k, np.inf)
    corners = corner_units[faces]
    middle, _ = unit_rows(corners.sum(axis=1))
    reach = np.sqrt(
        np.maximum(2.0 - 2.0 * np.einsum("mcj,mj->mc", corners, middle).min(axis=1), 0.0)
    )
    reach = reach * (1.0 + 1e-9) + 1e-12
    huge = reach >= np.sqrt(2.0) * (1.0 - 1e-9)
    everyone = np.arange(k)
    for face in np.flatnonzero(huge):
        _kdtree_test(points, faces, rays, everyone, np.full(k, face), hit_face, hit_depth)
    for members in _size_classes(reach, np.flatnonzero(~huge)):
        tree = cKDTree(middle[members])
        limit = float(reach[members].max())
        pending = np.arange(k)
        wanted = _FIRST_NEIGHBOURS
        while pending.size:
            count = min(wanted, len(members))
            distance, found = tree.query(rays[pending], k=count, distance_upper_bound=limit)
            distance = distance.reshape(len(pending), count)
            found = found.reshape(len(pending), count)
            within = np.isfinite(distance)
            query_rows, slot = np.nonzero(within)
            candidates = members[found[query_rows, slot]]
            queries = pending[query_rows]
            close = distance[query_rows, slot] <= reach[candidates]
            _kdtree_test(
                points, faces, rays, queries[close], candidates[close], hit_face, hit_depth
            )
            full = within[:, -1] & (count < len(members))
            pending = pending[full]
            wanted *= 4
    return hit_face


def _size_classes(reach: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
    if faces.size == 0:
        return []
    order = faces[np.argsort(reach[faces], kind="stable")]
    sizes = reach[order]
    smallest = max(float(sizes[0]), 1e-12)
    classes = np.floor(np.log2(np.maximum(sizes, smallest) / smallest)).astype(np.int64)
    return np.split(order, np.flatnonzero(np.diff(classes)) + 1)


def _kdtree_test(points, faces, rays, queries, candidates, hit_face, hit_depth) -> None:
    for start in range(0, len(queries), _CHUNK):
        q_ids = queries[start : start + _CHUNK]
        f_ids = candidates[start : start + _CHUNK]
        q = rays[q_ids]
        c0, c1, c2 = (points[faces[f_ids, i]] for i in range(3))
        e = np.stack(
            [
                np.einsum("kj,kj->k", q, np.cross(c1, c2)),
                np.einsum("kj,kj->k", q, np.cross(c2, c0)),
                np.einsum("kj,kj->k", q, np.cross(c0, c1)),
            ],
            axis=1,
        )
        total = e.sum(axis=1)
        scale = np.abs(e).sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inside = (np.sign(total)[:, None] * e >= _INSIDE * scale[:, None]).all(axis=1)
            inside &= total != 0.0
            depth = np.einsum("kj,kj->k", c0, np.cross(c1, c2)) / total
            inside &= depth > 0.0
        rows = np.flatnonzero(inside)
        if rows.size == 0:
            continue
        rows = rows[np.lexsort((depth[rows], q_ids[rows]))]
        first = np.ones(rows.size, dtype=bool)
        first[1:] = q_ids[rows][1:] != q_ids[rows][:-1]
        rows = rows[first]
        rows = rows[depth[rows] < hit_depth[q_ids[rows]]]
        hit_face[q_ids[rows]] = f_ids[rows]
        hit_depth[q_ids[rows]] = depth[rows]


# -- the report --------------------------------------------------------------------------


def ms(values: list[float]) -> float:
    return statistics.median(values) * 1e3


def rows_of(scalp: Scalp, served: dict, local: dict, queries: int) -> list[str]:
    title = f"scalp, {len(scalp.faces):,} faces"
    target = CLICK_TARGET_MS[scalp.subdivisions]
    click_ms = ms(served["seconds"])
    rate, peer_rate = queries / statistics.median(local["ours"]), None
    peer_rate = queries / statistics.median(local["peer"])
    per_face = local["index_bytes"] / len(scalp.faces)

    def row(measure, ours, peer="-", goal="-", met="-"):
        return f"| {title} | {measure} | {ours} | {peer} | {goal} | {met} |"

    return [
        row(
            f"one click end to end, curl (ms; GLB {served['upload'] / 1e6:.1f} MB)",
            f"{click_ms:,.0f}",
            "-",
            f"<= {target:.0f} ms",
            "yes" if click_ms <= target else "no",
        ),
        row("server timing of the last click (ms)", served["timing"].replace(", ", "; ")),
        row(
            "server peak RSS, fresh process (VmHWM, MiB): ready / after the clicks",
            f"{served['idle']:,.0f} / {served['peak']:,.0f}",
        ),
        row(
            "one click in-process, locate only (ms)",
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
            f"{queries:,} map points once the index exists (ms)",
            f"{ms(local['ours']):,.0f}",
            f"{ms(local['peer']):,.0f} (trees built in the call)",
        ),
        row(
            "queries per second once the index exists (on CPU time alone)",
            f"{rate / 1e6:.2f} M ({queries / statistics.median(local['ours_cpu']) / 1e6:.2f} M)",
            f"{peer_rate / 1e6:.2f} M",
            f">= {QUERIES_PER_SECOND / 1e6:.0f} M",
            "yes" if rate >= QUERIES_PER_SECOND else "no",
        ),
    ]


def measure(runs: int, queries: int) -> str:
    lines = [
        f"Scalp of `fsaverage-head.ply` subdivided 3 and 5 times, centre, rotation and sigma "
        f"({SIGMA}) given. End to end: one map point and the mesh as GLB posted by curl to a "
        f"fresh `meshflat serve` (one worker) on 127.0.0.1, median of {runs} runs after a "
        "warm-up. In-process: one thread, BLAS on one thread, median of "
        f"{runs} runs; the peer is the k-d tree version the index replaced, timed "
        "alternately in the same process (it builds its trees in every call).",
        "",
        "| region | measure | meshflat | k-d trees (before) | target | met |",
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
        footer(f"numpy {np.__version__}"),
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
