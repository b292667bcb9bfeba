"""Repeatability of the head's frame and of a follow-up's registration (``make
bench-repeat``): how far the map moves on the scalp when the landmarks are placed 2 mm off,
and how well a follow-up scan's map lands on the baseline's.

The scan: ``fsaverage-head.ply`` (millimetres), its landmarks the surface points nearest the
places ``tests.test_landmarks.NEAR`` gives, its scalp the anatomical region (10 mm above the
brow and the inion), sigma 0.3.

* Landmarks: 100 trials, each landmark moved by a random vector of length up to 2 mm (uniform
  in the ball). A scalp vertex's map point under the moved frame, read on the reference map
  (the correspondence of section 12), is a surface point: its distance to the vertex is how
  far the map moved there. Per trial the RMS and the largest over the scalp's vertices.
* A follow-up: the scan moved (a turn of about 40 degrees and a shift), 0.3 mm of noise on
  every vertex, its lowest 20 % of faces removed; registered without landmarks and with them
  (the landmarks moved with the scan, plus 2 mm of error). The transform's error (the largest
  over the scalp's vertices, mm, and the angle), and how far the zones drawn on the
  baseline's map land from the same surface on the follow-up: points of the baseline's map
  (a grid over the scalp's map, 2 mm apart on the surface or so) read on the baseline and on
  the follow-up's map (made with the answer's frame), the follow-up's point taken back by the
  true transform. The goal: the two scans' maps agree to within 1 mm on the scalp.

    python -m benchmarks.repeat_bench [--trials 100] [--write-docs]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.docs import publish
from benchmarks.measure_bench import progress
from benchmarks.transforms_bench import footer
from service.allocator import keep_large_blocks
from tests.conftest import load_sample
from tests.test_landmarks import on_head
from transforms import (
    LAYOUT_ORIENTATION,
    Chart,
    Frame,
    Landmarks,
    MapTriangles,
    PoleCap,
    flatten_region,
)
from transforms.registration import Surface, register

SIGMA = 0.3
OFFSET_MM = 10.0
LANDMARK_ERROR_MM = 2.0
TURN = Rotation.from_euler("zyx", [0.6, -0.3, 0.4])
SHIFT = np.array([30.0, -12.0, 8.0])
NOISE_MM, CROP = 0.3, 0.2
SEED = 7
CHART = Chart.distorted(PoleCap.from_sigma(SIGMA))


def scalp_map(vertices, faces, landmarks: Landmarks, region: np.ndarray) -> MapTriangles:
    """The map of the faces ``region`` in the landmarks' frame."""
    flat = flatten_region(vertices, faces[region], landmarks.frame(), CHART)
    return map_of(flat, vertices), flat


def map_of(flat, vertices: np.ndarray) -> MapTriangles:
    """The map's triangles of a flattened region of ``vertices``."""
    front = LAYOUT_ORIENTATION * flat.validation.winding
    return MapTriangles.of(flat.x, flat.y, vertices[flat.vertex_ids], flat.faces, front)


def read_on(triangles: MapTriangles, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The surface points the map shows at ``points`` ((n, 2)), and which it holds."""
    found, weights = triangles.locate(points)
    held = found >= 0
    surface = np.full((len(points), 3), np.nan)
    surface[held] = triangles.lift(found[held], weights[held])
    return surface, held


def landmark_trials(trials: int) -> list[str]:
    vertices, faces = load_sample("fsaverage-head.ply")
    vertices = np.array(vertices)
    reference = Landmarks.of(on_head(vertices))
    region = reference.scalp_faces(vertices, faces, OFFSET_MM)
    base, flat = scalp_map(vertices, faces, reference, region)
    on_scalp = vertices[flat.vertex_ids]
    rng = np.random.default_rng(SEED)
    rms, largest = [], []
    for trial in range(trials):
        if trial % 20 == 0:
            progress(f"landmarks: trial {trial + 1} of {trials}")
        moved = {}
        for name, point in on_head(vertices).items():
            direction = rng.normal(size=3)
            length = LANDMARK_ERROR_MM * rng.random() ** (1 / 3)  # uniform in the ball
            moved[name] = np.asarray(point) + length * direction / np.linalg.norm(direction)
        _, other = scalp_map(vertices, faces, Landmarks.of(moved), region)
        surface, held = read_on(base, np.column_stack([other.x, other.y]))
        gap = np.linalg.norm(surface[held] - on_scalp[held], axis=1)
        rms.append(float(np.sqrt(np.mean(gap**2))))
        largest.append(float(gap.max()))
    return [
        "",
        f"**Landmarks {LANDMARK_ERROR_MM:g} mm off** ({trials} trials, each landmark moved by a "
        f"random vector of up to {LANDMARK_ERROR_MM:g} mm; fsaverage's anatomical scalp, "
        f"{len(region):,} faces, {len(on_scalp):,} vertices): how far a scalp vertex's map "
        "point lands from it on the surface.",
        "",
        "| measure | median over trials (mm) | 95th percentile (mm) | worst trial (mm) |",
        "|---|---:|---:|---:|",
        f"| RMS over the scalp | {statistics.median(rms):.3f} | {np.percentile(rms, 95):.3f} "
        f"| {max(rms):.3f} |",
        f"| largest over the scalp | {statistics.median(largest):.3f} "
        f"| {np.percentile(largest, 95):.3f} | {max(largest):.3f} |",
    ]


def follow_up_rows() -> list[str]:
    vertices, faces = load_sample("fsaverage-head.ply")
    vertices = np.array(vertices)
    rng = np.random.default_rng(SEED)
    moved = TURN.apply(vertices) + SHIFT + rng.normal(scale=NOISE_MM, size=vertices.shape)
    height = vertices[faces].mean(axis=1)[:, 2]
    kept = faces[height > np.quantile(height, CROP)]
    truth_back = lambda p: TURN.inv().apply(p - SHIFT)  # noqa: E731  follow-up -> baseline
    reference = Landmarks.of(on_head(vertices))
    region = reference.scalp_faces(vertices, faces, OFFSET_MM)
    base, flat = scalp_map(vertices, faces, reference, region)
    # Map points over the scalp: the baseline's map sampled on a grid.
    x, y = flat.x, flat.y
    step = 0.01
    grid = np.stack(
        np.meshgrid(np.arange(x.min(), x.max(), step), np.arange(y.min(), y.max(), step)), -1
    ).reshape(-1, 2)
    on_base, held = read_on(base, grid)
    grid, on_base = grid[held], on_base[held]
    rows = []
    for seeded in ("moments", "landmarks"):
        progress(f"follow-up: registered from {seeded}")
        pairs = None
        if seeded == "landmarks":
            named = on_head(vertices)
            follow_marks = []
            for point in named.values():
                direction = rng.normal(size=3)
                follow_marks.append(
                    TURN.apply(np.asarray(point))
                    + SHIFT
                    + LANDMARK_ERROR_MM * direction / np.linalg.norm(direction)
                )
            pairs = (np.asarray(follow_marks), np.asarray(list(named.values())))
        start = time.perf_counter()
        found = register(
            Surface.of(moved, kept),
            Surface.of(vertices, faces),
            pairs,
            focus=Surface.of(vertices, faces[region]),
        )
        seconds = time.perf_counter() - start
        matrix = found.matrix
        ours = moved @ matrix[:3, :3].T + matrix[:3, 3]
        truth = truth_back(moved)
        scalp_vertices = np.unique(faces[region])
        error = np.linalg.norm(ours - truth, axis=1)[scalp_vertices]
        true_turn = TURN.inv().as_matrix()
        angle = np.degrees(Rotation.from_matrix(matrix[:3, :3] @ true_turn.T).magnitude())
        # The follow-up's map with the baseline's frame expressed for it.
        turn, shift = matrix[:3, :3], matrix[:3, 3]
        frame = reference.frame()
        follow_frame = Frame.from_matrix(frame.rotation @ turn, turn.T @ (frame.center - shift))
        # The follow-up's scalp: its faces above the baseline's boundary once registered.
        follow_region = reference.scalp_faces(ours, kept, OFFSET_MM)
        follow_flat = flatten_region(moved, kept[follow_region], follow_frame, CHART)
        follow_map = map_of(follow_flat, moved)
        on_follow, held = read_on(follow_map, grid)
        gap = np.linalg.norm(truth_back(on_follow[held]) - on_base[held], axis=1)
        within = "yes" if gap.max() <= 1.0 else "no"
        rows.append(
            f"| {seeded} | {seconds * 1e3:,.0f} | {error.max():.3f} | {angle:.3f} "
            f"| {np.sqrt(np.mean(gap**2)):.3f} | {gap.max():.3f} | {within} |"
        )
    return [
        "",
        f"**A follow-up** (the scan turned {np.degrees(TURN.magnitude()):.0f} degrees and shifted "
        f"{np.linalg.norm(SHIFT):.0f} mm, {NOISE_MM:g} mm of noise, the lowest {CROP:.0%} of its "
        f"faces removed), registered to the baseline on the anatomical scalp: the transform's "
        f"error over the scalp, and how far {len(grid):,} points of the baseline's map (a "
        "0.01 rad grid) land from the same surface on the follow-up's map.",
        "",
        "| started from | time (ms) | transform error, largest (mm) | angle (deg) "
        "| map points: RMS (mm) | largest (mm) | within 1 mm |",
        "|---|---:|---:|---:|---:|---:|---|",
        *rows,
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=100, help="landmark trials")
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    keep_large_blocks()
    lines = [
        "`fsaverage-head.ply` (millimetres), its landmarks as tests/test_landmarks.py places "
        f"them, its anatomical scalp {OFFSET_MM:g} mm above the brow and the inion, sigma "
        f"{SIGMA:g}.",
        *landmark_trials(args.trials),
        *follow_up_rows(),
        "",
        footer(f"numpy {np.__version__}"),
    ]
    publish(
        "repeat-bench",
        "The same map for every scan (`make bench-repeat`)",
        "\n".join(lines),
        args.write_docs,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
