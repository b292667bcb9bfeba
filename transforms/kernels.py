"""The compiled kernels' conventions, and their warm-up (docs/architecture.md, "numba").

The passes numpy cannot fuse (a face's measures in one read of its corners, the half-edges
grouped by edge, the weld's hash, the distortion's scans) are numba kernels. numba compiles a
kernel for each combination of argument types it meets, at the first call with them: seconds
each. So every kernel is called with one set of types (faces as C-contiguous
:data:`.arrays.INDEX`,
coordinates as C-contiguous float64, converted by the public function that calls it), and
:func:`compile_kernels` calls every one of them once, on a few faces: the service does it at
start-up (before it says it is ready) and the image's build does it so that the compiled code
is in the image (``cache=True`` keeps it, keyed by the source file and the CPU).

    python -m transforms.kernels      # compile (or load) every kernel, print the time
"""

from __future__ import annotations

import time

import numpy as np

from .arrays import INDEX
from .cap import PoleCap
from .chart import Chart
from .fit import fit_region
from .frames import Frame
from .locate import SORTED_QUERIES, LocateIndex
from .metrics import weighted_quantile
from .onmesh import MeshNearest
from .region import flatten_region
from .topology import face_components, welded


def compile_kernels() -> float:
    """Call every compiled kernel once: flatten a small closed surface seen from inside and
    from outside (the paths of a closed region, an open one and the exact tests), enough
    values for the quantiles' scans, a fit of half of it, nearest points on it and rays
    located on it, few and many; return the seconds it took."""
    start = time.perf_counter()
    vertices, faces = _octahedron_sphere()
    chart = Chart.distorted(PoleCap.from_sigma(0.3))
    for centre, kept in ((np.array([0.01, 0.02, 0.03]), faces), (np.zeros(3), faces[1:])):
        frame = Frame.from_pole_up(pole=[0.0, 1.0, 0.0], up=[0.0, 0.0, 1.0], center=centre)
        flatten_region(vertices, kept, frame, chart)
    # A fold seen from inside a closed surface: the parity of a ray's crossings decides.
    dented = vertices.copy()
    dented[0] *= -0.5
    flatten_region(dented, faces, Frame.identity(np.array([0.01, 0.02, 0.03])), chart)
    face_components(welded(faces, vertices))
    rng = np.random.default_rng(0)
    values = rng.random(70_000)
    weighted_quantile(values, values + 1.0, 0.5)
    # A fit of the sphere's upper half (its own kernels, transforms/fit/fused.py).
    fit_region(vertices, faces[vertices[faces].mean(axis=1)[:, 1] > 0.0])
    # Nearest points on the mesh (a registration's last rounds, transforms/onmesh.py).
    MeshNearest(vertices, faces).nearest(rng.normal(size=(8, 3)))
    # Locating rays: a few (the walk as they come) and many (sorted first).
    index = LocateIndex.build(vertices - [0.01, 0.02, 0.03], faces)
    for count in (16, SORTED_QUERIES):
        index.query(rng.normal(size=(count, 3)))
    return time.perf_counter() - start


def _octahedron_sphere() -> tuple[np.ndarray, np.ndarray]:
    """An octahedron's 8 faces each cut in four, on the unit sphere: (18, 3) float and
    (32, 3) :data:`.arrays.INDEX`, wound outwards."""
    vertices = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    octahedron = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4]]
    octahedron += [[2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    middles: dict[tuple[int, int], int] = {}

    def middle(a: int, b: int) -> int:
        key = (min(a, b), max(a, b))
        if key not in middles:
            middles[key] = len(vertices)
            point = np.add(vertices[a], vertices[b]) / 2.0
            vertices.append(list(point / np.linalg.norm(point)))
        return middles[key]

    faces = []
    for a, b, c in octahedron:
        ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
        faces += [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
    return np.array(vertices, dtype=np.float64), np.array(faces, dtype=INDEX)


if __name__ == "__main__":
    print(f"compiled kernels ready in {compile_kernels():.1f} s")
