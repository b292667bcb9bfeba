"""Benchmark of the strands (``make bench-strands``): guide hairs of 16 points grown from
10,000 and 100,000 sites on a 100k-face scalp, kept out of the whole head.

The head: ``fsaverage-head.ply`` (millimetres) subdivided 3 times, 259,968 faces; the region:
the faces the service's tests select (``region.cone``: axis +z, 70 degrees, its apex the
head's box centre), 97,875 faces, flattened as ``/v1/sites`` flattens a request with no
parameters (:func:`transforms.default_choice` at the middle of the region's box). On it, the
growth field of :mod:`benchmarks.growth_bench` (five flows and a whorl at the crown), sites
at the default spacing for the count (:func:`transforms.sites.place_sites`) and their
directions at 20 degrees off the scalp, all computed once, outside the timing.

Timed (median of several runs, one thread: ``IGL_NUM_THREADS``, ``OPENBLAS_NUM_THREADS`` and
``OMP_NUM_THREADS`` 1; the garbage collector off during each):

* the guard (:class:`transforms.strands.SurfaceGuard`: libigl's AABB tree over the head's
  259,968 faces) and the strands (:func:`transforms.strands.grow_strands`, 50 mm, 1 mm of
  clearance), the row the issue's targets are for: 10,000 strands at most 1 s, 100,000 at
  most 5 s;
* the same 10,000 curled (1.5 mm radius, 10 mm period, 32 points: a second pass of the guard
  over every point, and the walk of those it puts back);
* peak memory: the growth of 100,000 strands in a fresh process, its peak resident memory
  (``VmHWM``) above what it held before, by strand point, beside the budget the service
  charges for one (``STRAND_POINT_BYTES``, and ``CURL_POINT_BYTES`` more for a curled one),
  straight and curled;
* the answers: ``/v1/strands`` on the head's PLY through the service's own use-case and
  encoders in this process (the upload parsed, the fit, the sites, the strands, the form), its
  seconds and the size of each form for 100,000 strands, and the peak memory of the whole
  request by strand point (a fresh process each), beside what the service charges.

    IGL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 \\
        python -m benchmarks.strands_bench [--runs 3] [--write-docs]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np
import orjson
import trimesh

from benchmarks.docs import footer, publish
from benchmarks.growth_bench import CROWN, Scalp, around, draw
from benchmarks.measure_bench import progress, quiet
from benchmarks.server import status_bytes
from fixtures.meshes import subdivided
from service.capabilities import MESH_COMMANDS
from service.capabilities.context import Context
from service.capabilities.inputs import Upload, parse_params
from service.capabilities.strands import CURL_POINT_BYTES, STRAND_POINT_BYTES
from service.outputs import Output
from service.server.allocator import keep_large_blocks
from service.settings import Settings
from service.timings import Timings
from transforms import lift_curve
from transforms.arrays import triangle_areas
from transforms.growth import growth_field, pushed_forward
from transforms.sites import (
    SitePart,
    default_spacing,
    outward_sign,
    place_sites,
    site_normals,
    vertex_normals,
)
from transforms.strands import Curl, Roots, StrandShape, SurfaceGuard, grow_strands

SUBDIVISIONS = 3
HALF_ANGLE_DEG = 70.0
POINTS = 16
LENGTH_MM = 50.0
CLEARANCE_MM = 1.0
EXIT_ANGLE_DEG = 20.0
#: Strands, and the issue's target for them on one thread, in seconds.
TARGETS = {10_000: 1.0, 100_000: 5.0}
CURL = Curl(1.5, 10.0)
CURL_POINTS = 32
SEED = 2034
#: The forms of the answer whose sizes are reported, by their ``output``.
FORMS = (Output.JSON, Output.USD, Output.PLY, Output.GLB)


class Setting:
    """The head, its fitted scalp, the growth field and the guard's inputs, built once."""

    def __init__(self) -> None:
        self.vertices, self.faces = subdivided("fsaverage-head.ply", SUBDIVISIONS)
        self.scalp = Scalp.fitted(SUBDIVISIONS, HALF_ANGLE_DEG)
        self.triangles = self.scalp.triangles()
        drawn = draw(self.scalp)
        lifted = [lift_curve(self.triangles, flow) for flow in drawn.flows]
        self.field = growth_field(self.triangles, lifted, drawn.whorl,
                                  drawn.whorl_turns(self.triangles))  # fmt: skip
        points, faces = self.triangles.surface_points, self.triangles.faces
        self.outward = outward_sign(points, faces, self.scalp.frame.center)
        self.normals = self.outward * vertex_normals(points, faces)

    def roots(self, count: int) -> Roots:
        """``count`` sites at the default spacing, leaving at the exit angle."""
        points, faces = self.triangles.surface_points, self.triangles.faces
        area = triangle_areas(points, faces)
        part = SitePart(np.arange(len(area)), area, count, default_spacing(count / area.sum()))
        sites = place_sites(points, faces, [part], np.random.default_rng(SEED))
        normals = site_normals(points, faces, sites, self.scalp.frame.center)
        on_map = self.triangles.on_map(sites.triangles, sites.weights)
        tangent, _ = pushed_forward(self.triangles, sites.triangles,
                                    self.field.map_directions(on_map, sites.triangles),
                                    normals)  # fmt: skip
        rise = np.radians(EXIT_ANGLE_DEG)
        direction = np.cos(rise) * tangent + np.sin(rise) * normals
        return Roots(sites.points, direction, normals, sites.triangles, on_map)

    def grow(self, roots: Roots, shape: StrandShape) -> dict:
        """One timed growth: the guard built, then the strands (seconds each)."""
        start = time.perf_counter()
        guard = SurfaceGuard(self.vertices, self.faces, self.outward)
        built = time.perf_counter()
        lengths = np.full(len(roots.points), LENGTH_MM)
        strands = grow_strands(self.triangles, self.field, self.normals, roots, lengths, shape,
                               guard)  # fmt: skip
        done = time.perf_counter()
        return {"total": done - start, "guard": built - start, "grow": done - built,
                "strands": strands}  # fmt: skip


def plain_shape(points: int = POINTS) -> StrandShape:
    return StrandShape(points, CLEARANCE_MM, 2.0 * CLEARANCE_MM, 2.0)


def timed(setting: Setting, runs: int) -> list[tuple[str, int, int, list[dict]]]:
    """A warm-up, then ``runs`` growths of each case: (name, strands, points, runs)."""
    cases = [
        *((f"{count:,} strands", count, plain_shape()) for count in TARGETS),
        ("10,000 strands, curled", 10_000, curled_shape()),
    ]
    out = []
    for name, count, shape in cases:
        progress(f"placing {count:,} sites")
        roots = setting.roots(count)
        setting.grow(roots, shape)  # warm-up
        done = []
        for run in range(runs):
            progress(f"{name}: run {run + 1} of {runs}")
            done.append(quiet(lambda roots=roots, shape=shape: setting.grow(roots, shape)))
        out.append((name, len(roots.points), shape.points, done))
        check(done[-1]["strands"], shape)
    return out


def check(strands: np.ndarray, shape: StrandShape) -> None:
    """The strands asked: their shape, their arc lengths within 1 %."""
    assert strands.shape[1:] == (shape.points, 3) and np.isfinite(strands).all()
    arcs = np.linalg.norm(np.diff(strands, axis=1), axis=2).sum(axis=1)
    assert np.allclose(arcs, LENGTH_MM, rtol=0.01), np.abs(arcs / LENGTH_MM - 1).max()


def median_ms(runs: list[dict], key: str) -> float:
    return 1000.0 * statistics.median(run[key] for run in runs)


def timing_rows(cases) -> list[str]:
    rows = [
        "| strands | points | guard built (ms) | grown (ms) | total (ms) | per strand (µs) | "
        "target | met |",
        "|---|---:|---:|---:|---:|---:|---|---|",
    ]
    for name, count, points, runs in cases:
        total = median_ms(runs, "total")
        target = TARGETS.get(count) if "curled" not in name else None
        met = "-" if target is None else ("yes" if total <= 1000.0 * target else "**no**")
        rows.append(
            f"| {name} | {points} | {median_ms(runs, 'guard'):,.0f} | "
            f"{median_ms(runs, 'grow'):,.0f} | {total:,.0f} | {1000.0 * total / count:,.1f} | "
            f"{'-' if target is None else f'{target:g} s'} | {met} |"
        )
    return rows


# -- peak memory: a fresh process ------------------------------------------------------------


def curled_shape() -> StrandShape:
    return StrandShape(CURL_POINTS, CLEARANCE_MM, 2.0 * CLEARANCE_MM, 2.0, CURL)


def child(count: int, curled: bool) -> dict:
    """Peak memory of one growth of ``count`` strands (the guard built, the strands grown),
    above what the process held before it (after a warm-up on 1,000)."""
    keep_large_blocks()
    setting = Setting()
    shape = curled_shape() if curled else plain_shape()
    setting.grow(setting.roots(1_000), shape)
    roots = setting.roots(count)
    Path("/proc/self/clear_refs").write_text("5")  # VmHWM back to VmRSS
    before = status_bytes("VmRSS")
    setting.grow(roots, shape)
    return {"peak": status_bytes("VmHWM") - before, "strands": len(roots.points)}


def child_run(arguments: list[str]) -> dict:
    """This module run in a fresh process with ``arguments``: the JSON it prints last."""
    command = [sys.executable, "-m", "benchmarks.strands_bench", *arguments]
    env = os.environ | {"IGL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(command, check=True, capture_output=True, text=True, env=env)
    return json.loads(done.stdout.splitlines()[-1])


def peak_rows(count: int) -> list[str]:
    rows = [
        "| strands | points | peak above the start (MiB) | per strand point (B) | "
        "charged per point (B) |",
        "|---|---:|---:|---:|---:|",
    ]
    for curled, points, charged in (
        (False, POINTS, STRAND_POINT_BYTES),
        (True, CURL_POINTS, STRAND_POINT_BYTES + CURL_POINT_BYTES),
    ):
        measured = child_run(["--child", str(count), *(["--curled"] if curled else [])])
        per_point = measured["peak"] / (measured["strands"] * points)
        rows.append(
            f"| {measured['strands']:,}{', curled' if curled else ''} | {points} | "
            f"{measured['peak'] / 2**20:,.1f} | {per_point:,.0f} | {charged:,} |"
        )  # fmt: skip
    return rows


# -- the answers: the service's use-case and encoders ------------------------------------------


def service_answer(setting: Setting, count: int, output: Output) -> tuple[bytes, int]:
    """``/v1/strands`` on the head's PLY through the service's use-case and encoder, in this
    process: the answer's bytes and its strands."""
    capability = MESH_COMMANDS["strands"]
    data = trimesh.Trimesh(setting.vertices, setting.faces, process=False).export(file_type="ply")
    crown = setting.scalp.seen(around([CROWN[0]], [CROWN[1]]))[0]
    params = {
        "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": HALF_ANGLE_DEG}},
        "units": "mm", "count": count, "density_per_cm2": 1, "seed": 1,
        "length_mm": LENGTH_MM, "points": POINTS,
        "growth": {"whorls": [{"x": float(crown[0]), "y": float(crown[1]),
                               "turn": "clockwise"}],
                   "exit_angle_deg": EXIT_ANGLE_DEG},
    }  # fmt: skip
    ctx = Context(Settings.from_env())
    parsed = parse_params(capability.params, orjson.dumps(params))
    given = capability.input_of(parsed, {"mesh": Upload("head.ply", data)}, ctx)
    result = capability.operation(given, ctx)
    return capability.render(result, parsed, output, ctx, Timings()), len(result.points)


def answer_rows(setting: Setting, count: int) -> list[str]:
    """Each form's seconds and size, and the peak memory of the whole request by strand
    point (a fresh process each)."""
    rows = [
        "| form | seconds (parse, fit, sites, strands, form) | bytes | bytes per strand | "
        "peak of the request per strand point (B) |",
        "|---|---:|---:|---:|---:|",
    ]
    for output in FORMS:
        start = time.perf_counter()
        answer, strands = service_answer(setting, count, output)
        seconds = time.perf_counter() - start
        peak = child_run(["--answer-child", output.value, str(count)])["peak"]
        per_point = peak / (strands * POINTS)
        rows.append(f"| {output.value} | {seconds:.2f} | {len(answer):,} | "
                    f"{len(answer) / strands:,.0f} | {per_point:,.0f} |")  # fmt: skip
    rows.append(
        f"\n{strands:,} strands of {POINTS} points, {LENGTH_MM:g} mm. The peak counts "
        "everything the request holds above the process before it (the upload, the mesh, the "
        f"fit, the sites, the strands, the answer); the service charges {STRAND_POINT_BYTES:,} "
        "bytes a strand point beside what it charges for the mesh and the sites."
    )
    return rows


def answer_child(output: str, count: int) -> dict:
    """The peak memory of one ``/v1/strands`` request in this process, above the start (after
    a warm-up of 1,000 strands)."""
    keep_large_blocks()
    setting = Setting()
    service_answer(setting, 1_000, Output(output))
    Path("/proc/self/clear_refs").write_text("5")
    before = status_bytes("VmRSS")
    service_answer(setting, count, Output(output))
    return {"peak": status_bytes("VmHWM") - before}


def measure(runs: int) -> str:
    progress("the head, its scalp fitted, the growth field")
    setting = Setting()
    cases = timed(setting, runs)
    progress("peak memory (a fresh process)")
    peak = peak_rows(100_000)
    progress("the answers through the service's use-case")
    answers = answer_rows(setting, 100_000)
    lines = [
        f"Strands of {POINTS} points, {LENGTH_MM:g} mm, {CLEARANCE_MM:g} mm of clearance, on "
        f"`fsaverage-head.ply` subdivided {SUBDIVISIONS} times ({len(setting.faces):,} faces), "
        f"grown from sites on its {HALF_ANGLE_DEG:g}-degree cone ({len(setting.triangles):,} "
        f"faces) and kept out of the whole head; median of {runs} runs, one thread. The "
        "curled ones: radius 1.5 mm, period 10 mm.",
        "",
        *timing_rows(cases),
        "",
        "Peak memory of the growth of 100,000 strands, in a fresh process each:",
        "",
        *peak,
        "",
        "`/v1/strands` through the service's use-case and encoders in one process:",
        "",
        *answers,
        "",
        footer(f"numpy {np.__version__}", f"libigl {version('libigl')}"),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="timed runs of each (median)")
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--curled", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--answer-child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.curled)))
        return 0
    if args.answer_child:
        output, count = args.answer_child
        print(json.dumps(answer_child(output, int(count))))
        return 0
    keep_large_blocks()
    publish("strands-bench", "Strands (`make bench-strands`)", measure(args.runs),
            args.write_docs)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
