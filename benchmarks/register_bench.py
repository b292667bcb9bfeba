"""A follow-up registered to its baseline against small_gicp's own point-to-plane ICP (issue
37's registration rows; ``make bench-repeat``, or alone with ``--only-register``).

The scans: ``fsaverage-head.ply`` subdivided 3 times and decimated to 100,000 faces
(fast-simplification, through trimesh), and ``fsaverage-head.ply`` subdivided twice (64,992
faces). The follow-up of each: its baseline turned 10 degrees (about the axis (1, 2, 3)),
shifted 5 mm (along (1, -1, 1)), 0.1 mm of Gaussian noise on every coordinate of every vertex,
and the lowest 30 % of its faces (along z, the head's up) cut away. With landmarks: the
fixtures' five on the baseline (the vertices nearest fixtures/landmarks.py's spots), the
same points moved with the follow-up plus 2 mm of error each.

Timed on one thread, alternately in the same process (ours, then the peer, ``--runs`` times
after a warm-up of each; the median of the CPU times, :func:`timed`): meshflat's
:func:`transforms.registration.register` on the whole scans, from their meshes as read (the
samples, the global search without landmarks, ICP and the last rounds onto the baseline's
mesh); the peer, small_gicp's ``align`` with ``registration_type="PLANE_ICP"`` on the two
scans' vertices (its own preprocessing: a 1 mm voxel grid, normals of 20 neighbours, its
k-d tree; pairs within 20 mm, up to 100 iterations, ``num_threads=1``), from the identity
without landmarks and from the landmarks' least-squares transform with them (the start ours
takes). The service goes on from the whole scans to the region (the anatomical scalp here,
:func:`register_region`): its time and error are given too.

The error: the largest distance between a follow-up vertex mapped by the transform found
and by the true one, over all of the follow-up's vertices (mm). The noise floor: the median,
over 200 draws, of that largest distance for the least-squares fit of the follow-up's
vertices to the baseline's surface along its normals, whose error covariance is the noise's
variance times the inverse of the sum of ``J^T J`` (``J = [(x - c) x n, n]`` per vertex): no
fit of the surfaces alone does better on average (a peer that pairs each noisy vertex with
the very vertex it was made from has more to go on; see docs/benchmarks.md).
"""

from __future__ import annotations

import cProfile
import pstats
import statistics
import time
from dataclasses import dataclass

import numpy as np
import small_gicp
import trimesh
from scipy.spatial.transform import Rotation

from benchmarks.measure_bench import progress
from fixtures.landmarks import NEAR
from fixtures.meshes import subdivided
from transforms import Landmarks
from transforms.registration import (
    RegionScans,
    Surface,
    from_pairs,
    register,
    register_region,
)

TURN = Rotation.from_rotvec(np.radians(10.0) * np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0))
SHIFT = 5.0 * np.array([1.0, -1.0, 1.0]) / np.sqrt(3.0)
NOISE_MM, CROP, LANDMARK_ERROR_MM, SEED = 0.1, 0.3, 2.0, 5
#: The issue's targets: times small_gicp's, and the error (mm).
TARGETS = {"moments": 3.0, "landmarks": 2.0}
ACCURACY_MM = 0.01
PEER = {
    "registration_type": "PLANE_ICP",
    "downsampling_resolution": 1.0,
    "max_correspondence_distance": 20.0,
    "max_iterations": 100,
    "num_threads": 1,
}


@dataclass(frozen=True)
class Case:
    """A baseline, its follow-up and what is true of them."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    moved: np.ndarray  # the follow-up's vertices (moved, with noise)
    kept: np.ndarray  # the follow-up's faces
    scalp: np.ndarray  # the baseline's scalp faces
    pairs: tuple[np.ndarray, np.ndarray]  # landmarks: follow-up's, baseline's

    @property
    def used(self) -> np.ndarray:
        return np.unique(self.kept)

    @property
    def truth(self) -> np.ndarray:
        """The 4x4 transform taking the follow-up onto the baseline."""
        matrix = np.eye(4)
        matrix[:3, :3] = TURN.inv().as_matrix()
        matrix[:3, 3] = -TURN.inv().apply(SHIFT)
        return matrix

    def error(self, matrix: np.ndarray) -> float:
        points = self.moved[self.used]
        ours = points @ matrix[:3, :3].T + matrix[:3, 3]
        true = points @ self.truth[:3, :3].T + self.truth[:3, 3]
        return float(np.linalg.norm(ours - true, axis=1).max())


def make_case(name: str, vertices: np.ndarray, faces: np.ndarray, follow=None) -> Case:
    """The baseline ``vertices``, ``faces``; the follow-up made of ``follow`` (vertices and
    faces, already cropped) or of the baseline's own vertices, its lowest faces cut."""
    rng = np.random.default_rng(SEED)
    if follow is None:
        height = vertices[faces].mean(axis=1)[:, 2]
        follow = vertices, faces[height > np.quantile(height, CROP)]
    points, kept = follow
    moved = TURN.apply(points) + SHIFT + rng.normal(scale=NOISE_MM, size=points.shape)
    marks = {
        key: vertices[np.argmin(np.linalg.norm(vertices - np.asarray(spot), axis=1))]
        for key, spot in NEAR.items()
    }
    scalp = np.unique(Landmarks.of(marks).scalp_faces(vertices, faces, 10.0))
    base = np.asarray(list(marks.values()))
    error = rng.normal(size=base.shape)
    error *= LANDMARK_ERROR_MM / np.linalg.norm(error, axis=1)[:, None]
    pairs = (TURN.apply(base) + SHIFT + error, base)
    return Case(name, vertices, faces, moved, kept, scalp, pairs)


def decimated(vertices: np.ndarray, faces: np.ndarray, count: int):
    small = trimesh.Trimesh(vertices, faces, process=False)
    small = small.simplify_quadric_decimation(face_count=count)
    return np.asarray(small.vertices), np.asarray(small.faces, dtype=np.int64)


def cases() -> list[Case]:
    vertices, faces = subdivided("fsaverage-head.ply", 3)
    base = decimated(vertices, faces, 100_000)
    height = vertices[faces].mean(axis=1)[:, 2]
    own = decimated(vertices, faces[height > np.quantile(height, CROP)], 70_000)
    return [
        make_case("fsaverage subdivided 3 times, decimated to 100k faces", *base),
        make_case("fsaverage subdivided twice", *subdivided("fsaverage-head.ply", 2)),
        make_case("the first, the follow-up cut and decimated on its own (70k faces)", *base, own),
    ]


def noise_floor(case: Case, faces: np.ndarray, draws: int = 200) -> tuple[float, float]:
    """The median and the 90th percentile of the largest error over the follow-up's vertices
    of the least-squares fit of its vertices of ``faces`` to the baseline's surface (module
    doc)."""
    truth = case.truth
    every = case.moved[case.used] @ truth[:3, :3].T + truth[:3, 3]
    points = case.moved[np.unique(faces)] @ truth[:3, :3].T + truth[:3, 3]
    normals = Surface.of(case.vertices, case.faces).mesh.nearest(points).normals
    middle = points.mean(axis=0)
    jacobian = np.column_stack([np.cross(points - middle, normals), normals])
    covariance = NOISE_MM**2 * np.linalg.inv(jacobian.T @ jacobian)
    rng = np.random.default_rng(SEED)
    largest = []
    for delta in rng.multivariate_normal(np.zeros(6), covariance, size=draws):
        moved = np.cross(delta[:3], every - middle) + delta[3:]
        largest.append(float(np.linalg.norm(moved, axis=1).max()))
    return float(np.median(largest)), float(np.percentile(largest, 90))


def floors(case: Case) -> tuple[tuple[float, float], tuple[float, float]]:
    """The noise floors of the whole follow-up's fit and of its scalp's (its faces over the
    baseline's scalp under the true transform, as :meth:`RegionScans.over` chooses them)."""
    scans = RegionScans(case.moved, case.kept, case.vertices, case.faces, case.scalp)
    return noise_floor(case, case.kept), noise_floor(case, case.kept[scans.over(case.truth)])


def ours(case: Case, seeded: str) -> tuple[np.ndarray, np.ndarray, float]:
    """The whole scans' transform, the scalp's (the service's next step) and its own time."""
    pairs = case.pairs if seeded == "landmarks" else None
    scans = RegionScans(case.moved, case.kept, case.vertices, case.faces, case.scalp)
    whole = register(scans.follow, scans.base, pairs)
    start = time.process_time()
    on = register_region(scans, whole)
    return whole.matrix, on.found.matrix, time.process_time() - start


def peer(case: Case, seeded: str) -> np.ndarray:
    start = from_pairs(*case.pairs, scale=False) if seeded == "landmarks" else np.eye(4)
    found = small_gicp.align(
        case.vertices, case.moved[case.used], init_T_target_source=start, **PEER
    )
    return found.T_target_source


def timed(work, *args):
    """``work(*args)``'s CPU time (the process's: every thread's, were any started) and
    result. Both sides run on one thread; on a shared machine the CPU time is what each
    spent, where the wall time also counts what the other tenants did meanwhile."""
    start = time.process_time()
    result = work(*args)
    return time.process_time() - start, result


#: Where the time goes (:func:`profile_rows`): the functions' cumulative times under cProfile.
PARTS = (
    ("sampling both scans (`Surface.of`)", "of"),
    ("the baseline's normals and k-d tree for small_gicp (`Surface.cloud`)", "cloud"),
    ("the moment starts (`moment_starts`)", "moment_starts"),
    ("small_gicp's ICP stages, all of them (`_stages`)", "_stages"),
    ("... of which small_gicp's `align`", "align"),
    ("the last rounds onto the mesh (`on_mesh`)", "on_mesh"),
    ("... of which the nearest points (`_walk`, numba)", "_walk"),
    ("the faces around the baseline's vertices (`MeshNearest._around`)", "_around"),
    ("residuals and shares (`measured`)", "measured"),
)


def profile_rows(case: Case, runs: int = 5) -> list[str]:
    """The time of one registration of ``case`` per part (:data:`PARTS`), each seeding: the
    median over ``runs`` profiled runs (one alone swings with the machine's other work)."""
    times = {}
    for seeded in ("moments", "landmarks"):
        ours(case, seeded)  # warm
        parts: dict[str, list[float]] = {}
        for _ in range(runs):
            profile = cProfile.Profile()
            profile.enable()
            ours_whole(case, seeded)
            profile.disable()
            stats = pstats.Stats(profile)
            cumulative = {"": stats.total_tt}
            for (_, _, name), (_, _, _, total, _) in stats.stats.items():
                if name.startswith("<built-in method "):  # "<built-in method small_gicp.align>"
                    name = name.rstrip(">").rsplit(".", 1)[-1]
                cumulative[name] = cumulative.get(name, 0.0) + total
            for _, name in (*PARTS, ("", "")):
                parts.setdefault(name, []).append(cumulative.get(name, 0.0))
        times[seeded] = {name: statistics.median(values) for name, values in parts.items()}
    lines = [
        f"| {label} | {1e3 * times['moments'][name]:,.0f} | {1e3 * times['landmarks'][name]:,.0f} |"
        for label, name in PARTS
    ]
    total = [1e3 * times[seeded][""] for seeded in ("moments", "landmarks")]
    return [*lines, f"| all (under cProfile) | {total[0]:,.0f} | {total[1]:,.0f} |"]


def ours_whole(case: Case, seeded: str) -> np.ndarray:
    """The whole scans' registration alone, from the meshes."""
    pairs = case.pairs if seeded == "landmarks" else None
    follow, base = Surface.of(case.moved, case.kept), Surface.of(case.vertices, case.faces)
    return register(follow, base, pairs).matrix


def missed(case: Case, seeded: str, error: float, floor: tuple[float, float], peer: float) -> str:
    """Why a row misses the accuracy target, by how much."""
    over = 100.0 * (error / ACCURACY_MM - 1.0)
    return (
        f"{case.name}, {seeded}: {error:.4f} mm, {over:.0f} % over the target. The fit is the "
        "least-squares one of the follow-up's vertices to the baseline's mesh (the last "
        "rounds settle it to 1e-5 of the spread), so what is left is this noise draw's: the "
        f"noise floor's median is {floor[0]:.4f} mm and its 90th percentile {floor[1]:.4f}; "
        f"small_gicp's {peer:.4f} mm comes from pairing each noisy "
        "vertex with the very vertex it was made from, which a follow-up triangulated on its "
        "own (the third baseline) does not allow."
    )


def rows(runs: int, notes: list[str]) -> list[str]:
    lines = []
    for case in cases():
        (floor, floor_p90), (scalp_floor, _) = floors(case)
        for seeded in ("moments", "landmarks"):
            progress(f"register: {case.name}, {seeded}")
            times, peer_times, region_times = [], [], []
            for run in range(runs + 1):
                took, (whole, on_scalp, region_took) = timed(ours, case, seeded)
                peer_took, found = timed(peer, case, seeded)
                if run:  # the first: a warm-up
                    times.append(took - region_took)
                    region_times.append(region_took)
                    peer_times.append(peer_took)
            ms, peer_ms = 1e3 * statistics.median(times), 1e3 * statistics.median(peer_times)
            ratio, error = ms / peer_ms, case.error(whole)
            target = TARGETS[seeded]
            if error > ACCURACY_MM:
                notes.append(missed(case, seeded, error, (floor, floor_p90), case.error(found)))
            if ratio > target:
                notes.append(f"{case.name}, {seeded}: {ratio:.2f}x, over the {target:g}x target.")
            lines.append(
                f"| {case.name} | {seeded} | {ms:,.0f} | {peer_ms:,.0f} | {ratio:.2f}x "
                f"(target {target:g}x: {'met' if ratio <= target else 'missed'}) "
                f"| {error:.4f} ({'met' if error <= ACCURACY_MM else 'missed'}) "
                f"| {case.error(found):.4f} | {floor:.4f} "
                f"| {1e3 * statistics.median(region_times):,.0f} | {case.error(on_scalp):.4f} "
                f"| {scalp_floor:.4f} |"
            )
    return lines


def report(runs: int) -> str:
    notes: list[str] = []
    table = rows(runs, notes)
    first = cases()[0]
    return "\n".join(
        [
            "Issue 37's registration rows: a follow-up turned 10 degrees, shifted 5 mm, "
            f"{NOISE_MM:g} mm of noise per coordinate, the lowest {CROP:.0%} of its faces cut "
            "away, registered to its baseline on one thread by meshflat (`register`, whole scans)"
            " and by small_gicp's point-to-plane ICP (its `align` on the vertices, 1 mm voxels, "
            f"pairs within 20 mm), timed alternately in one process, the median CPU time of {runs}"
            " runs after a warm-up; without landmarks the peer starts from the identity, with "
            "them both start from the landmarks' least-squares transform (each landmark "
            f"{LANDMARK_ERROR_MM:g} mm off). Errors: the largest over every follow-up vertex of "
            "the distance between it mapped by the transform found and by the true one (mm); the "
            "noise floor is what a least-squares fit of the follow-up's vertices to the "
            "baseline's surface gets, as a median (`benchmarks/register_bench.py`). The last "
            "three columns: the service's next step, the scalp region to region "
            "(`register_region`), on top, and the noise floor of a fit of the scalp alone.",
            "",
            "| baseline | started from | meshflat (ms) | small_gicp (ms) | ratio "
            f"| meshflat error (target {ACCURACY_MM:g}) | small_gicp error | noise floor "
            "| then on the scalp (ms) | error after the scalp | its noise floor |",
            "|---|---|---:|---:|---|---|---:|---:|---:|---:|---:|",
            *table,
            "",
            "Targets missed:" if notes else "Every target met.",
            "",
            *[f"* {note}" for note in notes],
            "",
            f"Where the time goes on the first baseline ({first.name}; ms of one "
            "registration under cProfile, each part's time with what it calls, the median of 5):",
            "",
            "| part | without landmarks | with landmarks |",
            "|---|---:|---:|",
            *profile_rows(first),
        ]
    )
