"""Benchmark of pictures coloured by distortion (``make bench-picture``).

The region: ``make bench-measure``'s million-face scalp (``fsaverage-head.ply`` subdivided 5
times, narrowed to 52 degrees: 1,000,968 faces), flattened with fixed parameters, as the
service holds it (:class:`service.capabilities.region.resolve.MeshRegion`). Its map coloured
by isometric distortion (``colour_by: "isometric"``), 1200 x 800 pixels, on one thread (BLAS
too), the service's allocator settings, median of several runs after a warm-up:

* meshflat: the renderers of ``/v1/flatten``
  (:data:`service.capabilities.region.pictures.RENDERERS`), from the flattened region to the
  answer's bytes: the faces' distortion measured, the colours
  and bar, the picture described, the raster (each pixel its triangle's colour, exactly),
  the encoding. Targets (the issue): PNG 1 s, SVG 1.5 s; the SVG's size is reported (its
  fill is at most one run a 2 x 2 cell of the plot).
* the peer, timed alternately in the same process: Pillow's ``ImageDraw.polygon`` filling
  each triangle with its colour on the same canvas (the same colours, computed once,
  untimed), then the PNG encoding.

    python -m benchmarks.picture_bench [--runs 5] [--write-docs]
"""

from __future__ import annotations

import io
import statistics
import time
from importlib.metadata import version

import numpy as np
from PIL import Image, ImageDraw

from benchmarks.docs import run_report
from benchmarks.measure_bench import HALF_ANGLE_DEG, SIGMA, SUBDIVISIONS, progress
from fixtures.meshes import subdivided
from service.capabilities.context import Context
from service.capabilities.flatten import FlattenParams
from service.capabilities.region.pictures import RENDERERS, face_colouring
from service.capabilities.region.resolve import MeshRegion, Selection
from service.meshio import Mesh
from service.outputs import Output
from service.outputs.colours import ColourBy
from transforms import Chart, Frame, Framing, Layout, PoleCap, flatten_region
from transforms.selection import RegionPieces

TARGETS = {Output.PNG: 1.0, Output.SVG: 1.5}
WIDTH, HEIGHT = 1200, 800
#: No memory budget: the renderers charge nothing here.
CONTEXT = Context()


def region() -> MeshRegion:
    vertices, faces = subdivided("fsaverage-head.ply", SUBDIVISIONS)
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - centre
    cosine = directions[:, 2] / np.linalg.norm(directions, axis=1)
    chosen = np.flatnonzero(cosine >= np.cos(np.radians(HALF_ANGLE_DEG)))
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], centre)
    chart = Chart.distorted(PoleCap.from_sigma(SIGMA))
    flat = flatten_region(vertices, faces[chosen], frame, chart)
    mesh = Mesh(vertices=vertices, faces=faces, format="ply")
    pieces = RegionPieces(np.array([len(chosen)]), chosen[:0])
    selection = Selection(chosen, centre, {"faces": "..."}, pieces)
    return MeshRegion(mesh, selection, chart, frame, flat, None)


def peer_png(corners: np.ndarray, colours: np.ndarray) -> bytes:
    canvas = Image.new("RGB", (WIDTH, HEIGHT), "#ffffff")
    draw = ImageDraw.Draw(canvas)
    for triangle, colour in zip(corners.tolist(), colours.tolist(), strict=True):
        draw.polygon([tuple(point) for point in triangle], fill=tuple(colour))
    out = io.BytesIO()
    canvas.save(out, format="PNG", compress_level=6)
    return out.getvalue()


def measure(runs: int) -> str:
    progress("building the region (1M faces) and flattening it")
    flattened = region()
    params = FlattenParams.model_validate(
        {"colour_by": "isometric", "image_width": WIDTH, "image_height": HEIGHT}
    )
    flat = flattened.flat
    framing = Framing.of(flat.x, flat.y, Layout.THETA_PHI, WIDTH, HEIGHT)
    corners = framing.pixels(np.column_stack([flat.x, flat.y]))[flat.faces] - 0.5
    colours = face_colouring(flattened, ColourBy.ISOMETRIC)[0]
    progress("warm-up")
    sizes = {output: len(RENDERERS[output](flattened, params, CONTEXT)) for output in TARGETS}
    times: dict[str, list[float]] = {"png": [], "svg": [], "peer": []}
    for run in range(runs):
        progress(f"run {run + 1} of {runs}")
        for output in TARGETS:
            start = time.perf_counter()
            RENDERERS[output](flattened, params, CONTEXT)
            times[output.value].append(time.perf_counter() - start)
        start = time.perf_counter()
        peer_png(corners, colours)
        times["peer"].append(time.perf_counter() - start)
    median = {key: statistics.median(value) * 1e3 for key, value in times.items()}

    def met(output: Output) -> str:
        return "yes" if median[output.value] <= TARGETS[output] * 1e3 else "no"

    pillow = f"Pillow `ImageDraw.polygon` {version('pillow')}, a call a triangle, then PNG"
    lines = [
        f"The region: {len(flat.faces):,} faces; coloured by isometric distortion; "
        f"{WIDTH} x {HEIGHT} pixels; one thread; median of {runs} runs after a warm-up.",
        "",
        "| renderer | time (ms) | target | met | size |",
        "|---|---:|---|---|---:|",
        f"| meshflat PNG (from the flattened region: distortion, colours, raster, encoding) "
        f"| {median['png']:,.0f} | <= 1,000 ms | {met(Output.PNG)} "
        f"| {sizes[Output.PNG] / 1e3:,.0f} kB |",
        f"| meshflat SVG (the same, the fill as runs of 2 x 2 cells) | {median['svg']:,.0f} "
        f"| <= 1,500 ms | {met(Output.SVG)} | {sizes[Output.SVG] / 1e3:,.0f} kB |",
        f"| {pillow} (the colours given) | {median['peer']:,.0f} | - | - | - |",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    return run_report(
        argv,
        __doc__,
        "picture-bench",
        "Pictures coloured by distortion (`make bench-picture`)",
        measure,
    )


if __name__ == "__main__":
    raise SystemExit(main())
