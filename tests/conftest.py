"""Shared fixtures: the bundled sample meshes and small constructed meshes; the marks that
`make test` selects and distributes by."""

from __future__ import annotations

import contextlib
import io
import math
import os
from collections import Counter
from fractions import Fraction
from functools import cache

import httpx
import numpy as np
import pytest
import trimesh
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from service.app import create_app
from service.samples import SAMPLES
from service.settings import Settings

# Local runs explore new examples each time; CI (HYPOTHESIS_PROFILE=ci) replays a fixed,
# larger set so a red build always means the same thing. No timing deadlines: speed is the
# benchmarks' business.
settings.register_profile("dev", deadline=None)
settings.register_profile("ci", deadline=None, derandomize=True, max_examples=300)
#: A longer search, run by hand: HYPOTHESIS_PROFILE=long pytest tests/test_gltf_fuzz.py
settings.register_profile("long", deadline=None, max_examples=5000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))

#: A case that takes over about 4 s alone on a core: `make test` leaves it out, `make test`
#: with MESHFLAT_ALL_TESTS=1 (CI) runs it (the marker is registered in pyproject.toml).
slow = pytest.mark.slow
#: Tests that start real servers (``meshflat serve``, and Chromium against one) and time
#: them: `make test` (pytest-xdist, ``--dist loadgroup``) runs them one after another on one
#: worker, so that no two servers share the machine's cores and a module's server is
#: started once.
real_servers = pytest.mark.xdist_group("real-servers")


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """On a pytest-xdist worker, refuse a collection that the workers would share out wrongly
    without a word: the scheduler keys tests by node id (a repeated id runs once), and with
    ``--dist loadgroup`` it groups by the ``@group`` suffix that xdist adds to the ids of
    xdist_group tests (a pytest whose node ids it cannot change loses the groups)."""
    if not hasattr(config, "workerinput"):
        return
    repeated = sorted(nodeid for nodeid, n in Counter(i.nodeid for i in items).items() if n > 1)
    if repeated:
        raise pytest.UsageError(f"tests share node ids, so xdist would run them once: {repeated}")
    if config.getvalue("loadgroup"):
        lost = [
            i.nodeid for i in items if i.get_closest_marker("xdist_group") and "@" not in i.nodeid
        ]
        if lost:
            raise pytest.UsageError(f"xdist_group is not applied to {lost[:3]} ...: check pytest")


@cache
def load_sample(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and faces (m, 3) of a bundled sample, in the file's order."""
    data = SAMPLES[name].path.read_bytes()
    mesh = trimesh.load(
        io.BytesIO(data), file_type=name.rsplit(".", 1)[1], process=False, force="mesh"
    )
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    vertices.flags.writeable = False
    faces.flags.writeable = False
    return vertices, faces


@contextlib.asynccontextmanager
async def started(settings: Settings):
    """An httpx client of an app started (its lifespan run) with ``settings``."""
    app = create_app(settings)
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as c:
            yield c


@pytest.fixture
async def client():
    """An httpx client of a started app with the default settings."""
    async with started(Settings()) as c:
        yield c


@pytest.fixture
def anyio_backend():
    """Async tests (marked ``anyio``) run on asyncio, as uvicorn does."""
    return "asyncio"


def unit_rows(draw_array: np.ndarray) -> np.ndarray:
    """Normalise rows, for strategies that drew non-zero vectors."""
    return draw_array / np.linalg.norm(draw_array, axis=1, keepdims=True)


#: (n, 3) arrays of directions, each row non-zero, normalised.
directions = (
    hnp.arrays(
        np.float64,
        st.tuples(st.integers(1, 40), st.just(3)),
        elements=st.floats(-1.0, 1.0, allow_nan=False, width=64),
    )
    .filter(lambda a: bool((np.linalg.norm(a, axis=1) > 1e-3).all()))
    .map(unit_rows)
)

#: Warp parameters across the accepted range, denser near the useful middle.
sigmas = st.one_of(
    st.floats(0.02, 5.0), st.floats(1e-6, 1e6), st.sampled_from([0.3, 1.0, 1e-6, 1e6])
)


def sphere_mesh(rings: int, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere around +Y: vertex (j, k) at polar angle pi j / rings from +Y and longitude
    2 pi k / segments (longitude 0 towards +Z, 90 degrees towards +X); poles are single
    vertices. Faces wind counter-clockwise seen from outside.

    Returns vertices (n, 3) and faces (m, 3).
    """
    polar = np.linspace(0.0, np.pi, rings + 1)[1:-1]
    longitude = 2.0 * np.pi * np.arange(segments) / segments
    a, lam = np.meshgrid(polar, longitude, indexing="ij")
    ring_points = np.stack(
        [np.sin(a) * np.sin(lam), np.cos(a), np.sin(a) * np.cos(lam)], axis=-1
    ).reshape(-1, 3)
    vertices = np.vstack([[0.0, 1.0, 0.0], ring_points, [0.0, -1.0, 0.0]])
    top, bottom = 0, len(vertices) - 1

    def ring(j: int, k: int) -> int:
        return 1 + j * segments + k % segments

    faces = []
    for k in range(segments):
        faces.append([top, ring(0, k + 1), ring(0, k)])
        faces.append([bottom, ring(rings - 2, k), ring(rings - 2, k + 1)])
        for j in range(rings - 2):
            faces.append([ring(j, k), ring(j, k + 1), ring(j + 1, k)])
            faces.append([ring(j + 1, k), ring(j, k + 1), ring(j + 1, k + 1)])
    # The rows above run clockwise seen from outside; reverse them.
    return vertices, np.ascontiguousarray(np.array(faces, dtype=np.int64)[:, ::-1])


def grid_mesh(xs: np.ndarray, ys: np.ndarray, z: float) -> tuple[np.ndarray, np.ndarray]:
    """A triangulated grid in the plane ``z``; each cell split along its (0,0)-(1,1) diagonal,
    faces counter-clockwise seen from +Z.

    Returns vertices (len(xs) * len(ys), 3) and faces (m, 3).
    """
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    vertices = np.stack([gx, gy, np.full_like(gx, z)], axis=-1).reshape(-1, 3)
    ny = len(ys)
    faces = []
    for i in range(len(xs) - 1):
        for j in range(ny - 1):
            a, b, c, d = i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1
            faces.append([a, b, c])
            faces.append([a, c, d])
    return vertices, np.array(faces, dtype=np.int64)


def exact_sign(a, b, c) -> int:
    """Sign of det[a, b, c] in rational arithmetic (every float is a rational)."""
    a, b, c = ([Fraction(float(v)) for v in row] for row in (a, b, c))
    det = (
        a[0] * (b[1] * c[2] - b[2] * c[1])
        + a[1] * (b[2] * c[0] - b[0] * c[2])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
    )
    return (det > 0) - (det < 0)


#: The scalps of the samples: faces whose centroid lies within an angle of the top axis, seen
#: from a point inside the head (None: the box centre; Lee Perry-Smith's box holds the
#: shoulders, and from there the cone would take in the ears).
SCALPS = {
    "fsaverage-head.ply": (None, 2, 70.86),
    "lee-perry-smith.obj": ((0.0, 1.5, 0.0), 1, 70.0),
}


def scalp(name: str = "fsaverage-head.ply"):
    """The sample and its scalp (:data:`SCALPS`)."""
    vertices, faces = load_sample(name)
    centre, top, half_angle_deg = SCALPS[name]
    if centre is None:
        centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - np.asarray(centre)
    cosine = directions[:, top] / np.linalg.norm(directions, axis=1)
    return vertices, faces[cosine >= math.cos(math.radians(half_angle_deg))]
