"""Repeatability of the head's frame and of a follow-up's registration (``make
bench-repeat``), on every sample scan: how far the map moves on the scalp when the landmarks
are placed 2 mm off, and how well a follow-up scan's map lands on the baseline's.

Per scan: its landmarks are the surface points nearest hand-placed spots (fixtures/landmarks.py;
for the goat, the same anatomy: between the eyes, the back of the skull, the fronts of the ear
openings), its scalp the anatomical region 10 mm above the brow and the inion, sigma 0.3.
Scans without units are read with a tragi distance of 145 mm. Distances are measured on the
map's trusted triangles only (those neither folded, back-facing, degenerate, nor across the
seam or a singular point): where a map folds, a point on it has no single place on the head.

* Landmarks: 100 trials, each landmark moved by a random vector of length up to 2 mm (uniform
  in the ball). A scalp vertex's map point under the moved frame, read on the reference map
  (the correspondence of section 12), is a surface point: its distance to the vertex is how
  far the map moved there. Per trial the RMS and the largest over the scalp's vertices.
* A follow-up: the scan moved (a turn of about 40 degrees and a shift of 33 mm), 0.3 mm of
  noise on every vertex, its lowest 20 % of faces along the head's up removed; registered
  without landmarks and with them (moved with the scan, plus 2 mm of error). The transform's
  error (the largest over the scalp's vertices, mm, and the angle), and how far the zones
  drawn on the baseline's map land from the same surface on the follow-up: points of the
  baseline's map (a 0.01 rad grid) read on the baseline and on the follow-up's map (made with
  the answer's frame), the follow-up's point taken back by the true transform. The goal: the
  two scans' maps agree to within 1 mm on the scalp.

Then issue 37's registration rows against small_gicp (benchmarks/register_bench.py), which
``--only-register`` runs alone.

    python -m benchmarks.repeat_bench [--trials 100] [--runs 5] [--only-register] [--write-docs]
"""

from __future__ import annotations

import argparse
import io
import statistics
import time
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from benchmarks import register_bench
from benchmarks.docs import footer, publish
from benchmarks.measure_bench import progress
from fixtures.landmarks import NEAR, NEAR_GOAT, NEAR_LEE_PERRY_SMITH, NEAR_NEFERTITI
from fixtures.zoo import available, scan_bytes
from service.server.allocator import keep_large_blocks
from transforms import (
    LAYOUT_ORIENTATION,
    Chart,
    Frame,
    Landmarks,
    MapTriangles,
    PoleCap,
    flatten_region,
)
from transforms.registration import (
    RegionScans,
    RegistrationAmbiguous,
    register,
    register_region,
)

SIGMA = 0.3
OFFSET_MM = 10.0
LANDMARK_ERROR_MM = 2.0
#: The tragi's distance assumed for a scan without units, mm.
TRAGI_MM = 145.0
TURN = Rotation.from_euler("zyx", [0.6, -0.3, 0.4])
SHIFT_MM = np.array([30.0, -12.0, 8.0])
NOISE_MM, CROP = 0.3, 0.2
SEED = 7
CHART = Chart.distorted(PoleCap.from_sigma(SIGMA))


@dataclass(frozen=True)
class Scan:
    """A sample scan, the spots its landmarks are placed nearest, and its unit (None: from
    ``TRAGI_MM``)."""

    name: str
    near: dict
    mm_per_unit: float | None
    what: str


SCANS = (
    Scan("fsaverage-head.ply", NEAR, 1.0, "head, mm"),
    Scan("lee-perry-smith.obj", NEAR_LEE_PERRY_SMITH, None, "head and shoulders"),
    Scan("nefertiti-lowres.obj", NEAR_NEFERTITI, 1.0, "bust; its scalp is the crown"),
    Scan("goathead.obj", NEAR_GOAT, None, "goat; horns on the scalp"),
)


@dataclass(frozen=True)
class Head:
    """A scan loaded: its surface, landmarks, scale and anatomical scalp."""

    scan: Scan
    vertices: np.ndarray
    faces: np.ndarray
    marks: dict
    mm: float  # mesh units per millimetre
    region: np.ndarray

    @classmethod
    def of(cls, scan: Scan) -> Head:
        mesh = trimesh.load(
            io.BytesIO(scan_bytes(scan.name)),
            file_type=scan.name.rsplit(".", 1)[1],
            process=False,
            force="mesh",
        )
        vertices = np.asarray(mesh.vertices, dtype=float)
        faces = np.asarray(mesh.faces, dtype=np.int64)
        marks = {
            name: vertices[np.argmin(np.linalg.norm(vertices - np.asarray(spot), axis=1))]
            for name, spot in scan.near.items()
        }
        landmarks = Landmarks.of(marks)
        mm = landmarks.width / TRAGI_MM if scan.mm_per_unit is None else 1 / scan.mm_per_unit
        region = landmarks.scalp_faces(vertices, faces, OFFSET_MM * mm)
        return cls(scan, vertices, faces, marks, mm, region)

    @property
    def landmarks(self) -> Landmarks:
        return Landmarks.of(self.marks)


def trusted_map(flat, vertices: np.ndarray) -> MapTriangles:
    """The map's trusted triangles of a flattened region of ``vertices``."""
    check = flat.validation
    flagged = np.concatenate(
        [
            check.folded_faces,
            check.backfacing_faces,
            check.degenerate_faces,
            check.seam_faces,
            check.singular_point_faces,
        ]
    )
    kept = np.setdiff1d(np.arange(len(flat.faces)), flagged)
    front = LAYOUT_ORIENTATION * check.winding
    return MapTriangles.of(flat.x, flat.y, vertices[flat.vertex_ids], flat.faces[kept], front)


def read_on(triangles: MapTriangles, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The surface points the map shows at ``points`` ((n, 2)), and which it holds."""
    found, weights = triangles.locate(points)
    held = found >= 0
    surface = np.full((len(points), 3), np.nan)
    surface[held] = triangles.lift(found[held], weights[held])
    return surface, held


def trusted_vertices(flat) -> np.ndarray:
    """The flattened vertices (positions in ``flat.x``) of its trusted triangles."""
    check = flat.validation
    flagged = np.concatenate(
        [check.folded_faces, check.backfacing_faces, check.degenerate_faces, check.seam_faces]
    )
    kept = np.setdiff1d(np.arange(len(flat.faces)), flagged)
    return np.unique(flat.faces[kept])


def landmark_row(head: Head, trials: int) -> tuple[str, dict]:
    v, f, region = head.vertices, head.faces, head.region
    flat = flatten_region(v, f[region], head.landmarks.frame(), CHART)
    base = trusted_map(flat, v)
    kept = trusted_vertices(flat)
    on_scalp = v[flat.vertex_ids]
    rng = np.random.default_rng(SEED)
    rms, largest = [], []
    for trial in range(trials):
        if trial % 25 == 0:
            progress(f"{head.scan.name} landmarks: trial {trial + 1} of {trials}")
        moved = {}
        for name, point in head.marks.items():
            direction = rng.normal(size=3)
            length = LANDMARK_ERROR_MM * head.mm * rng.random() ** (1 / 3)  # uniform in ball
            moved[name] = point + length * direction / np.linalg.norm(direction)
        other = flatten_region(v, f[region], Landmarks.of(moved).frame(), CHART)
        points = np.column_stack([other.x, other.y])[kept]
        surface, held = read_on(base, points)
        gap = np.linalg.norm(surface[held] - on_scalp[kept][held], axis=1) / head.mm
        rms.append(float(np.sqrt(np.mean(gap**2))))
        largest.append(float(gap.max()))
    check = flat.validation
    flagged = len(np.union1d(check.folded_faces, check.backfacing_faces))
    return (
        f"| {head.scan.name} ({head.scan.what}) | {len(region):,} | {flagged:,} "
        f"| {statistics.median(rms):.3f} | {np.percentile(rms, 95):.3f} "
        f"| {statistics.median(largest):.3f} | {np.percentile(largest, 95):.3f} "
        f"| {max(largest):.3f} |"
    )


def follow_up_rows(head: Head) -> list[str]:
    v, f, region, mm = head.vertices, head.faces, head.region, head.mm
    rng = np.random.default_rng(SEED)
    shift = SHIFT_MM * mm
    moved = TURN.apply(v) + shift + rng.normal(scale=NOISE_MM * mm, size=v.shape)
    up = head.landmarks.axes()[2]
    height = v[f].mean(axis=1) @ up
    kept = f[height > np.quantile(height, CROP)]
    truth_back = lambda p: TURN.inv().apply(p - shift)  # noqa: E731  follow-up -> baseline
    reference = head.landmarks
    flat = flatten_region(v, f[region], reference.frame(), CHART)
    base = trusted_map(flat, v)
    x, y = flat.x, flat.y
    step = 0.01
    grid = np.stack(
        np.meshgrid(np.arange(x.min(), x.max(), step), np.arange(y.min(), y.max(), step)), -1
    ).reshape(-1, 2)
    on_base, held = read_on(base, grid)
    grid, on_base = grid[held], on_base[held]
    rows = []
    for seeded in ("moments", "landmarks"):
        progress(f"{head.scan.name} follow-up: registered from {seeded}")
        pairs = None
        if seeded == "landmarks":
            follow_marks = []
            for point in head.marks.values():
                direction = rng.normal(size=3)
                error = LANDMARK_ERROR_MM * mm * direction / np.linalg.norm(direction)
                follow_marks.append(TURN.apply(point) + shift + error)
            pairs = (np.asarray(follow_marks), np.asarray(list(head.marks.values())))
        start = time.perf_counter()
        try:
            scans = RegionScans(moved, kept, v, f, np.unique(region))
            whole = register(scans.follow, scans.base, pairs, last="sparse")  # as the service
            found = register_region(scans, whole).found
        except RegistrationAmbiguous as refused:
            rows.append(f"| {head.scan.name} | {seeded} | refused: {refused} | | | | | |")
            continue
        seconds = time.perf_counter() - start
        matrix = found.matrix
        ours = moved @ matrix[:3, :3].T + matrix[:3, 3]
        error = np.linalg.norm(ours - truth_back(moved), axis=1)[np.unique(f[region])] / mm
        true_turn = TURN.inv().as_matrix()
        angle = np.degrees(Rotation.from_matrix(matrix[:3, :3] @ true_turn.T).magnitude())
        # The follow-up's map with the baseline's frame expressed for it.
        turn, move = matrix[:3, :3], matrix[:3, 3]
        frame = reference.frame()
        follow_frame = Frame.from_matrix(frame.rotation @ turn, turn.T @ (frame.center - move))
        # The follow-up's scalp: its faces above the baseline's boundary once registered.
        follow_region = reference.scalp_faces(ours, kept, OFFSET_MM * mm)
        follow_flat = flatten_region(moved, kept[follow_region], follow_frame, CHART)
        on_follow, held = read_on(trusted_map(follow_flat, moved), grid)
        gap = np.linalg.norm(truth_back(on_follow[held]) - on_base[held], axis=1) / mm
        within = float(np.mean(gap <= 1.0))
        rows.append(
            f"| {head.scan.name} | {seeded} | {seconds * 1e3:,.0f} | {error.max():.3f} "
            f"| {angle:.3f} | {len(gap):,} | {np.sqrt(np.mean(gap**2)):.3f} | {gap.max():.3f} "
            f"| {within:.2%} |"
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=100, help="landmark trials per scan")
    parser.add_argument("--runs", type=int, default=5, help="timed runs per registration row")
    parser.add_argument(
        "--only-register", action="store_true", help="only the registration rows against small_gicp"
    )
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    keep_large_blocks()
    if not args.only_register:
        same_map(args)
    publish(
        "repeat-register",
        "A follow-up registered, against small_gicp (`make bench-repeat`)",
        register_bench.report(args.runs)
        + "\n\n"
        + footer(f"numpy {np.__version__}", f"small_gicp {small_gicp_version()}"),
        args.write_docs,
    )
    return 0


def small_gicp_version() -> str:
    from importlib.metadata import version

    return version("small_gicp")


def same_map(args) -> None:
    heads = [Head.of(scan) for scan in SCANS if available(scan.name)]
    landmark_rows = [landmark_row(head, args.trials) for head in heads]
    follow_rows = [row for head in heads for row in follow_up_rows(head)]
    lines = [
        "Every sample scan, its landmarks placed by hand (the surface points nearest the spots "
        "`benchmarks/repeat_bench.py` names), its anatomical scalp "
        f"{OFFSET_MM:g} mm above the brow and the inion, sigma {SIGMA:g}; scans without units "
        f"read with a tragi distance of {TRAGI_MM:g} mm. Distances are over the map's trusted "
        "triangles (a folded map has no single place on the head).",
        "",
        f"**Landmarks {LANDMARK_ERROR_MM:g} mm off** ({args.trials} trials per scan, each "
        f"landmark moved by a random vector of up to {LANDMARK_ERROR_MM:g} mm): how far a "
        "scalp vertex's map point lands from it on the surface, mm.",
        "",
        "| scan | scalp faces | folded or back-facing | RMS: median | RMS: p95 "
        "| largest: median | largest: p95 | largest: worst trial |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
        *landmark_rows,
        "",
        f"**A follow-up** (the scan turned {np.degrees(TURN.magnitude()):.0f} degrees and "
        f"shifted {np.linalg.norm(SHIFT_MM):.0f} mm, {NOISE_MM:g} mm of noise, the lowest "
        f"{CROP:.0%} of its faces along the head's up removed), registered to the baseline on "
        "the anatomical scalp: the transform's error over the scalp, and how far the points of "
        "the baseline's map (a 0.01 rad grid over its trusted triangles) land from the same "
        "surface on the follow-up's map.",
        "",
        "| scan | started from | time (ms) | transform error, largest (mm) | angle (deg) "
        "| map points | RMS (mm) | largest (mm) | share within 1 mm |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
        *follow_rows,
        "",
        "The rule of section 14 is made for human heads. On the bust, whose scalp is its "
        "crown, and on the goat, whose horns rise from its scalp, the centre it gives sees "
        "parts of the scalp from behind (the folded or back-facing faces above); there a map "
        "point can lie on two sheets of the surface, and the maps of two scans, or of two "
        "placements of the landmarks, differ by where those sheets lie.",
        "",
        footer(f"numpy {np.__version__}"),
    ]
    publish(
        "repeat-bench",
        "The same map for every scan (`make bench-repeat`)",
        "\n".join(lines),
        args.write_docs,
    )


if __name__ == "__main__":
    raise SystemExit(main())
