"""Whether a region closes round its centre (transforms/enclosure.py): known without a free-cap
search, checked against probe directions by brute force."""

import numpy as np
import pytest

from transforms import Chart, Frame, PoleCap
from transforms.enclosure import ray_crossings
from transforms.region import flatten_region

from .conftest import load_sample, sphere_mesh

CHART = Chart.distorted(PoleCap.from_sigma(0.3))


def _probes(count: int) -> np.ndarray:
    k = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1 - 2 * k / count), np.pi * (1 + 5**0.5) * k
    return np.stack(
        [np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], axis=1
    )


def _covered(vertices, faces, centre, probes) -> np.ndarray:
    """(p,) bool: whether each probe direction lies in the cone from ``centre`` over a face
    (the same side of its three edge planes, ahead)."""
    a, b, c = (vertices[faces[:, i]] - centre for i in range(3))
    sides = [np.cross(p, q) @ probes.T for p, q in ((a, b), (b, c), (c, a))]
    inside = (sides[0] >= 0) & (sides[1] >= 0) & (sides[2] >= 0)
    inside |= (sides[0] <= 0) & (sides[1] <= 0) & (sides[2] <= 0)
    return (inside & ((a + b + c) @ probes.T > 0)).any(axis=0)


def _flat(vertices, faces, centre):
    frame = Frame.from_pole_up(pole=[0.0, 1.0, 0.0], up=[0.0, 0.0, 1.0], center=centre)
    return flatten_region(vertices, faces, frame, CHART)


def test_a_closed_head_with_overhangs_encloses_its_box_centre():
    """Lee Perry-Smith's whole head is closed, and seen from its box centre it folds (the
    ears and the nose overhang): it has outline edges, yet covers every direction."""
    vertices, faces = load_sample("lee-perry-smith.obj")
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    v = _flat(vertices, faces, centre).validation
    assert len(v.boundary_edges) == 0 and len(v.backfacing_faces) > 0
    assert v.encloses_centre
    assert _covered(vertices, faces, centre, _probes(400)).all()


def test_a_closed_surface_seen_from_outside_does_not_enclose_the_centre():
    vertices, faces = sphere_mesh(12, 24)
    centre = np.array([0.0, 0.0, 3.0])
    v = _flat(vertices, faces, centre).validation
    assert not v.encloses_centre
    assert not _covered(vertices, faces, centre, _probes(400)).all()


def test_an_open_region_is_not_said_to_enclose_however_much_it_covers():
    """A sphere with one triangle removed covers all but a sliver: not closed, so nothing
    is claimed (the free-cap search measures it)."""
    vertices, faces = sphere_mesh(12, 24)
    v = _flat(vertices, faces[1:], np.zeros(3)).validation
    assert not v.encloses_centre and len(v.boundary_edges) == 3


def test_two_nested_spheres_round_the_centre_enclose_it_having_no_outline():
    """Each ray crosses two shells, an even count, but seen from the centre both shells are
    smooth: no outline edge, which is enough."""
    vertices, faces = sphere_mesh(10, 20)
    nested = np.vstack([vertices, 0.5 * vertices])
    both = np.vstack([faces, faces + len(vertices)])
    flat = _flat(nested, both, np.zeros(3))
    assert flat.validation.encloses_centre


@pytest.mark.parametrize("seed", range(5))
def test_a_generic_ray_from_inside_a_sphere_crosses_it_once(seed):
    vertices, faces = sphere_mesh(10, 20)
    flat = _flat(vertices, faces, np.array([0.1, -0.2, 0.05]))
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=3)
    measures = _measures(flat, vertices, np.array([0.1, -0.2, 0.05]))
    assert ray_crossings(measures, direction / np.linalg.norm(direction)) == 1


def test_a_ray_through_a_vertex_is_not_generic():
    vertices, faces = sphere_mesh(10, 20)
    measures = _measures(_flat(vertices, faces, np.zeros(3)), vertices, np.zeros(3))
    # The sphere's pole is a vertex at (0, 1, 0): the ray along +Y meets the fan round it at
    # that vertex exactly.
    assert np.array_equal(vertices[np.argmax(vertices[:, 1])], [0.0, 1.0, 0.0])
    assert ray_crossings(measures, np.array([0.0, 1.0, 0.0])) is None


def _measures(flat, vertices, centre):
    from transforms.faces import measure_faces

    frame = Frame.from_pole_up(pole=[0.0, 1.0, 0.0], up=[0.0, 0.0, 1.0], center=centre)
    return measure_faces(
        frame.to_local(vertices[flat.vertex_ids]), flat.faces, flat.theta, flat.phi, CHART.cap
    )
