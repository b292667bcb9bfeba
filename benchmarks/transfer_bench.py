"""Benchmark of values carried between the map and the mesh (``make bench-transfer``).

The region: ``make bench-measure``'s, ``fsaverage-head.ply`` subdivided 5 times and its scalp
narrowed to 52 degrees (1,000,968 faces, one disk), flattened with fixed parameters. Its map
is framed as the PNG answer frames it (:class:`transforms.Framing`) on a
4096 x 4096 grid and on a 2048 x 2048 one.

* Image to mesh (4096 x 4096, a smooth grey image): meshflat's per-face means
  and per-vertex values, as ``/v1/transfer`` computes them (:func:`transforms.pixels.onto_mesh`:
  the pixel runs, running sums, the small faces' samples, the coverage, the vertices read
  from the pixels the map holds). Target
  (the issue): 1 s.
* Mesh to image (2048 x 2048): a value a vertex drawn linear inside every triangle
  (:func:`transforms.pixels.vertex_image`, with the face-id image). Target: 0.5 s.

The peer, timed alternately in the same process: Pillow's ``ImageDraw.polygon`` filling each
triangle with its id on an int32 image (one call a triangle), then the same numpy work on the
id image (``np.bincount`` means; the affine values per pixel). Its fill rule differs from
(16.1) on shared edges: the share of pixels where the two id images agree is reported, and
the per-face means' largest difference over faces both fill.

meshflat on one thread and on two (``threads``, numpy releasing the GIL); BLAS on one thread;
the service's allocator settings; median of the runs after a warm-up.

    python -m benchmarks.transfer_bench [--runs 5] [--write-docs]
"""

from __future__ import annotations

import statistics
import time
from importlib.metadata import version

import numpy as np
from PIL import Image, ImageDraw

from benchmarks.docs import run_report
from benchmarks.measure_bench import Region, progress
from transforms import Framing, Layout, pixels

#: The issue's targets, seconds.
TARGET_TO_MESH, TARGET_TO_IMAGE = 1.0, 0.5
BIG, SMALL = 4096, 2048


def corners_on(region: Region, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The region's triangles (m, 3, 2) and vertices (k, 2) in pixels of a size x size PNG
    answer's framing."""
    framing = Framing.of(region.x, region.y, Layout.THETA_PHI, size, size)
    at = framing.pixels(np.column_stack([region.x, region.y]))
    return at[region.faces], at


def smooth_image(size: int) -> np.ndarray:
    rows, columns = np.mgrid[0:size, 0:size] / size
    return 0.5 + 0.25 * np.sin(6 * columns) * np.cos(4 * rows)


def ours_to_mesh(faces, at, image, threads: int) -> np.ndarray:
    """What ``/v1/transfer`` computes of an image part: :func:`transforms.pixels.onto_mesh`."""
    _, means, _ = pixels.onto_mesh(at, faces, image, threads=threads)
    return means


def ours_to_image(corners, values, threads: int) -> np.ndarray:
    image, _ = pixels.vertex_image(corners, values, SMALL, SMALL, threads)
    return image


def pillow_ids(corners: np.ndarray, size: int) -> np.ndarray:
    """(size, size) int: each triangle filled with its id by ``ImageDraw.polygon`` (its
    corners shifted by half a pixel: Pillow puts pixel centres on integers)."""
    canvas = Image.new("I", (size, size), -1)
    draw = ImageDraw.Draw(canvas)
    shifted = corners - 0.5
    for face, triangle in enumerate(shifted.tolist()):
        draw.polygon([tuple(point) for point in triangle], fill=face)
    return np.asarray(canvas)


def peer_to_mesh(corners, image) -> tuple[np.ndarray, np.ndarray]:
    ids = pillow_ids(corners, BIG).ravel()
    held = ids >= 0
    count = np.bincount(ids[held], minlength=len(corners))
    total = np.bincount(ids[held], weights=image.ravel()[held], minlength=len(corners))
    with np.errstate(divide="ignore", invalid="ignore"):
        return total / count, ids


def peer_to_image(corners, values) -> np.ndarray:
    ids = pillow_ids(corners, SMALL)
    plane = pixels.planes(corners, values)
    rows, columns = np.nonzero(ids >= 0)
    a, b, c = plane[ids[rows, columns]].T
    image = np.zeros((SMALL, SMALL))
    image[rows, columns] = a + b * (columns + 0.5) + c * (rows + 0.5)
    return image


def timed(work) -> tuple[float, object]:
    start = time.perf_counter()
    result = work()
    return time.perf_counter() - start, result


def measure(runs: int) -> str:
    progress("building the region (1M faces) and flattening it")
    region = Region.flattened()
    big, at_big = corners_on(region, BIG)
    small, _ = corners_on(region, SMALL)
    image = smooth_image(BIG)
    # A smooth value a vertex: the map's x and y mixed.
    per_vertex = np.sin(region.x * 3) + np.cos(region.y * 2)
    values = per_vertex[region.faces]
    progress("warm-up")
    ours_to_mesh(region.faces, at_big, image, 1)
    ours_to_image(small, values, 1)
    times: dict[str, list[float]] = {k: [] for k in ("m1", "m2", "i1", "i2", "pm", "pi")}
    peer_means = peer_ids = peer_image = None
    for run in range(runs):
        progress(f"run {run + 1} of {runs}")
        times["m1"].append(timed(lambda: ours_to_mesh(region.faces, at_big, image, 1))[0])
        times["m2"].append(timed(lambda: ours_to_mesh(region.faces, at_big, image, 2))[0])
        seconds, (peer_means, peer_ids) = timed(lambda: peer_to_mesh(big, image))
        times["pm"].append(seconds)
        times["i1"].append(timed(lambda: ours_to_image(small, values, 1))[0])
        times["i2"].append(timed(lambda: ours_to_image(small, values, 2))[0])
        seconds, peer_image = timed(lambda: peer_to_image(small, values))
        times["pi"].append(seconds)
    ours_means = ours_to_mesh(region.faces, at_big, image, 1)
    ours_ids = pixels.face_ids(big, BIG, BIG).ravel()
    agree_ids = float(np.mean(ours_ids == peer_ids))
    # Where they differ, whether the two triangles are neighbours (share a corner).
    differ = np.flatnonzero((ours_ids != peer_ids) & (ours_ids >= 0) & (peer_ids >= 0))
    a, b = region.faces[ours_ids[differ]], region.faces[peer_ids[differ]]
    neighbours = float(np.mean((a[:, :, None] == b[:, None, :]).any(axis=(1, 2))))
    one_only = float(np.mean((ours_ids >= 0) != (peer_ids >= 0)))
    both = np.isfinite(peer_means) & np.isfinite(ours_means)
    mean_gap = float(np.abs(peer_means[both] - ours_means[both]).max())
    ours_image = ours_to_image(small, values, 1)
    same = (pixels.face_ids(small, SMALL, SMALL) == pillow_ids(small, SMALL)) & (ours_image != 0)
    image_gap = float(np.abs(ours_image - peer_image)[same].max())
    median = {key: statistics.median(value) * 1e3 for key, value in times.items()}

    def row(name: str, key: str, target: float | None) -> str:
        met = "-" if target is None else ("yes" if median[key] <= target * 1e3 else "no")
        goal = "-" if target is None else f"<= {target * 1e3:,.0f} ms"
        return f"| {name} | {median[key]:,.1f} | {goal} | {met} |"

    pillow = f"Pillow `ImageDraw.polygon` {version('pillow')}, a call a triangle"

    def table(keys: tuple[str, str, str], target: float) -> list[str]:
        one, two, peer = keys
        return [
            "| rasteriser | time (ms) | target | met |",
            "|---|---:|---|---|",
            row("meshflat, one thread", one, target),
            row("meshflat, two threads", two, target),
            row(f"{pillow}, then numpy", peer, None),
        ]

    lines = [
        f"The region: {len(region.faces):,} faces, {len(region.x):,} vertices; median of {runs} "
        "runs after a warm-up.",
        "",
        f"**Image to mesh** ({BIG} x {BIG} grey image: a value a face, its mean over the "
        "triangle, and a value a vertex):",
        "",
        *table(("m1", "m2", "pm"), TARGET_TO_MESH),
        "",
        f"**Mesh to image** (a value a vertex drawn on a {SMALL} x {SMALL} grid, linear inside "
        "each triangle):",
        "",
        *table(("i1", "i2", "pi"), TARGET_TO_IMAGE),
        "",
        f"Agreement: the two face-id images agree on {agree_ids:.2%} of the {BIG}² pixels; "
        f"{one_only:.2%} are held by one rule only (the region's border: Pillow fills a "
        "polygon's outline too), and of the pixels both give to different triangles "
        f"{neighbours:.2%} go to two neighbours (sharing a corner): the fill rules differ on "
        f"shared edges. The per-face means differ by at most {mean_gap:.3g} (grey 0 to 1); "
        f"where both give a pixel to the same triangle the drawn values differ by at most "
        f"{image_gap:.3g} (values -2 to 2).",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    return run_report(
        argv,
        __doc__,
        "transfer-bench",
        "Values between the map and the mesh (`make bench-transfer`)",
        measure,
    )


if __name__ == "__main__":
    raise SystemExit(main())
