"""Honest numbers (issue 31): a triangle the map stretches beyond the bound is flagged as
stretched, left out of the trusted metrics and counted in a zone's flagged area; the
summaries give a median; captions quote the trusted median and p95 with the flagged count;
the pictures' axes are in the layout's own coordinates, the ones zones are read in.
Through the API; every number checked against a brute force of its own."""

from __future__ import annotations

import itertools
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from transforms import STRETCHED_ENERGY

from .test_api import flatten, obj_of

pytestmark = pytest.mark.anyio

SVG = "{http://www.w3.org/2000/svg}"
#: The plane x = 1 seen from the origin with the world's axes: phi near 0, theta near 90 deg.
PLANE_PARAMS = {"method": "standard", "center": [0.0, 0.0, 0.0], "rotation": "identity"}
#: Vertex 0, a corner of the grid, pulled far down the plane: its one triangle is a long
#: sliver whose map, seen from the origin, is squeezed (energy about 84), not flipped.
SLIVER_CORNER = [1.0, -0.4, -4.0]
SLIVER_FACE = 0


def stretched_plane() -> tuple[np.ndarray, np.ndarray]:
    """A 5 x 5 grid on the plane x = 1 (y, z in [-0.4, 0.4]) with corner 0 pulled far."""
    n = 5
    ys, zs = np.meshgrid(np.linspace(-0.4, 0.4, n), np.linspace(-0.4, 0.4, n), indexing="ij")
    vertices = np.column_stack([np.ones(n * n), ys.ravel(), zs.ravel()])
    vertices[0] = SLIVER_CORNER
    cells = [
        (i * n + j, i * n + j + 1, (i + 1) * n + j) for i in range(n - 1) for j in range(n - 1)
    ]
    faces = [f for a, b, c in cells for f in ([a, c, c + 1], [a, c + 1, b])]
    return vertices, np.asarray(faces)


async def post_plane(client, params: dict, endpoint: str = "/v1/flatten"):
    vertices, faces = stretched_plane()
    data = obj_of(vertices, faces)
    return await flatten(client, "plane.obj", params, data=data, endpoint=endpoint)


def brute_energies(vertices, faces, x, y) -> np.ndarray:
    """(m,) isometric energy of each face: the singular values of the affine map from the 3D
    triangle (in its own plane) to its layout triangle, the layout scaled once so that its
    area is the 3D area (docs/math.md, section 7), by SVD."""
    p = vertices[faces]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    u = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    normal = np.cross(e1, e2)
    w = np.cross(normal / np.linalg.norm(normal, axis=1, keepdims=True), u)
    source = np.stack(  # (m, 2, 2): the edges in the triangle's own plane, as columns
        [
            np.stack([(e1 * u).sum(1), (e1 * w).sum(1)], 1),
            np.stack([(e2 * u).sum(1), (e2 * w).sum(1)], 1),
        ],
        axis=2,
    )
    q = np.stack([x, y], axis=1)[faces]
    target = np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]], axis=2)
    area3d = 0.5 * np.linalg.norm(normal, axis=1)
    area2d = 0.5 * np.abs(np.linalg.det(target))
    target = target * np.sqrt(area3d.sum() / area2d.sum())
    s = np.linalg.svd(target @ np.linalg.inv(source), compute_uv=False)
    return (s**2 + s**-2.0).sum(axis=1) / 4.0


def brute_summary(values: np.ndarray, weights: np.ndarray) -> dict:
    """Weighted mean, the smallest values with half and 95 % of the weight at or below them,
    and the maximum."""
    order = np.argsort(values)
    share = np.cumsum(weights[order]) / weights.sum()
    quantile = lambda q: values[order][np.argmax(share >= q)]  # noqa: E731
    return {
        "mean": float(np.average(values, weights=weights)),
        "p50": float(quantile(0.5)),
        "p95": float(quantile(0.95)),
        "max": float(values.max()),
    }


async def test_a_stretched_sliver_is_flagged_and_left_out_of_the_trusted_metrics(client):
    response = await post_plane(client, PLANE_PARAMS)
    assert response.status_code == 200, response.text
    answer = response.json()
    vertices, faces = stretched_plane()
    ids = np.asarray(answer["vertices"]["ids"])
    x, y = np.zeros(len(vertices)), np.zeros(len(vertices))
    x[ids], y[ids] = answer["vertices"]["x"], answer["vertices"]["y"]
    energy = brute_energies(vertices, faces, x, y)
    assert energy[SLIVER_FACE] > 5 * STRETCHED_ENERGY
    v = answer["validation"]
    assert v["stretched_faces"] == np.flatnonzero(energy > STRETCHED_ENERGY).tolist()
    assert v["stretched_faces"] == [SLIVER_FACE]
    # Stretched, not flipped: the region is still star-shaped and nothing else flags it.
    assert v["star_shaped"] and v["seam_free"]
    for key in ("folded_faces", "backfacing_faces", "degenerate_faces", "seam_faces"):
        assert v[key] == []
    p = vertices[faces]
    areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    metrics = answer["metrics"]
    everything = brute_summary(energy, areas)
    rest = np.ones(len(faces), dtype=bool)
    rest[SLIVER_FACE] = False
    trusted = brute_summary(energy[rest], areas[rest])
    for stat in ("mean", "p50", "p95", "max"):
        assert metrics["isometric"][stat] == pytest.approx(everything[stat], rel=1e-9)
        assert metrics["trusted"]["isometric"][stat] == pytest.approx(trusted[stat], rel=1e-9)
    assert metrics["trusted"]["faces"] == len(faces) - 1
    assert metrics["trusted"]["flagged_faces"] == 1
    # The sliver is a large share of the area: the mean over all faces is many times the
    # trusted mean, which it no longer moves.
    assert metrics["isometric"]["mean"] > 2 * metrics["trusted"]["isometric"]["mean"]


async def test_a_zone_counts_the_stretched_area_as_flagged(client):
    answer = (await post_plane(client, PLANE_PARAMS)).json()
    x, y = np.asarray(answer["vertices"]["x"]), np.asarray(answer["vertices"]["y"])
    zone = {
        "name": "all",
        "outer": {
            "x": [x.min() - 1, x.max() + 1, x.max() + 1, x.min() - 1],
            "y": [y.min() - 1, y.min() - 1, y.max() + 1, y.max() + 1],
        },
    }
    response = await post_plane(client, {**PLANE_PARAMS, "zones": [zone]}, "/v1/measure")
    assert response.status_code == 200, response.text
    (measured,) = response.json()["zones"]
    vertices, faces = stretched_plane()
    p = vertices[faces[SLIVER_FACE]]
    sliver = 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]))
    assert measured["area_flagged"] == pytest.approx(sliver, rel=1e-9)
    assert measured["area"] > measured["area_flagged"] > 0


async def test_sites_may_go_on_a_stretched_face(client):
    """A stretched face's map is one to one: it stays open to sites (docs/math.md, 6)."""
    params = {**PLANE_PARAMS, "units": "m", "density_per_cm2": 0.01, "seed": 1}
    response = await post_plane(client, params, "/v1/sites")
    assert response.status_code == 200, response.text
    (zone,) = response.json()["zones"]
    vertices, faces = stretched_plane()
    p = vertices[faces]
    total = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    assert zone["open_area_cm2"] == pytest.approx(total * 1e4, rel=1e-9)
    assert zone["open_area_cm2"] == pytest.approx(zone["area_cm2"], rel=1e-12)


async def test_the_caption_quotes_the_trusted_median_and_p95_and_the_flagged_count(client):
    answer = (await post_plane(client, PLANE_PARAMS)).json()
    energy = answer["metrics"]["trusted"]["isometric"]
    for output in ("svg", "png"):
        response = await post_plane(client, {**PLANE_PARAMS, "output": output})
        assert response.status_code == 200, response.text
    svg = (await post_plane(client, {**PLANE_PARAMS, "output": "svg"})).text
    root = ET.fromstring(svg)
    captions = [t.text for t in root.iter(f"{SVG}text") if t.get("class") == "caption"]
    expected = (
        f"isometric energy p50 {energy['p50']:.3f}, p95 {energy['p95']:.3f} on the trusted "
        "faces (1 flagged, 1 of them stretched)"
    )
    assert any(expected in line for line in captions), captions
    assert "mean" not in " ".join(captions)
    legend = " ".join(t.text or "" for t in root.find(f".//{SVG}g[@class='legend']"))
    assert f"stretched (isometric > {STRETCHED_ENERGY:g}): 1" in legend


def axis_ticks(root) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
    """The SVG's (pixel, value) ticks of the x axis (columns) and the y axis (rows), read
    from the tick marks and their labels."""
    axes = root.find(f".//{SVG}g[@class='axes']")
    children = list(axes)
    x_ticks, y_ticks = [], []
    for line, text in itertools.pairwise(children):
        if line.tag != f"{SVG}line" or text.tag != f"{SVG}text":
            continue
        value = float(text.text)
        if line.get("x1") == line.get("x2"):  # a vertical mark: the x axis
            x_ticks.append((float(line.get("x1")), value))
        else:
            y_ticks.append((float(line.get("y1")), value))
    return x_ticks, y_ticks


def corner_pixels(root) -> np.ndarray:
    """(k, 2) every triangle corner the SVG draws, in canvas pixels."""
    numbers = []
    for path in root.iter(f"{SVG}path"):
        if (path.get("class") or "").startswith("triangles"):
            numbers += re.findall(r"-?\d+(?:\.\d+)?", path.get("d"))
    return np.asarray(numbers, dtype=float).reshape(-1, 2)


@pytest.mark.parametrize(
    ("layout", "y_title", "y_down"),
    [
        ("theta_phi", "y = theta (layout units, rad)", True),
        ("mercator", "y = ln tan((pi - theta) / 2) (layout units)", False),
    ],
)
async def test_the_pictures_axes_read_in_the_layouts_coordinates(client, layout, y_title, y_down):
    """The ticks are labelled with the layout's x and y: read back through them, the drawn
    triangles span exactly the answer's vertices, and a zone drawn between ticks has area."""
    name = "fsaverage-head.ply"
    params = {
        "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}},
        "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
        "sigma": 0.3,
        "layout": layout,
    }
    answer = (await flatten(client, name, params)).json()
    assert answer["validation"]["seam_free"]  # every triangle is drawn
    root = ET.fromstring((await flatten(client, name, {**params, "output": "svg"})).content)
    titles = [t.text for t in root.find(f".//{SVG}g[@class='axes']") if t.tag == f"{SVG}text"]
    assert "x = phi (layout units, rad)" in titles and y_title in titles
    x_ticks, y_ticks = axis_ticks(root)
    assert len(x_ticks) >= 3 and len(y_ticks) >= 3
    corners = corner_pixels(root)
    x, y = np.asarray(answer["vertices"]["x"]), np.asarray(answer["vertices"]["y"])
    for ticks, drawn, values, sign in (
        (x_ticks, corners[:, 0], x, 1.0),
        (y_ticks, corners[:, 1], y, 1.0 if y_down else -1.0),  # Mercator's y runs up
    ):
        pixels, labels = np.asarray(ticks).T
        slope, offset = np.polyfit(labels, pixels, 1)  # pixel = offset + slope * value
        # Labels are rounded to the tick step's digits: the fit is exact to the SVG's 0.1 px.
        assert np.abs(offset + slope * labels - pixels).max() < 0.06
        assert np.sign(slope) == sign
        read = (drawn - offset) / slope
        tolerance = 0.15 / abs(slope)  # the SVG writes pixels to 0.1
        assert read.min() == pytest.approx(values.min(), abs=tolerance)
        assert read.max() == pytest.approx(values.max(), abs=tolerance)
    # The point at the ticks nearest the map's middle, sent to /v1/locate (which takes theta
    # and phi: y is theta, or Mercator's ln tan((pi - theta) / 2)), is found in a triangle
    # whose corners, weighted as the hit says, are that very point of the layout.
    at_x = min((v for _, v in x_ticks), key=lambda v: abs(v - x.mean()))
    at_y = min((v for _, v in y_ticks), key=lambda v: abs(v - y.mean()))
    theta = at_y if layout == "theta_phi" else np.pi - 2.0 * np.arctan(np.exp(at_y))
    query = {**params, "theta": [theta], "phi": [at_x], "via": "map"}
    located = await flatten(client, name, query, endpoint="/v1/locate")
    assert located.status_code == 200, located.text
    (hit,) = located.json()["hits"]
    position = {v: k for k, v in enumerate(answer["vertices"]["ids"])}
    row = answer["faces"]["ids"].index(hit["face"])
    corners = [position[v] for v in answer["faces"]["vertices"][row]]
    weights = np.asarray(hit["barycentric"])
    assert weights @ x[corners] == pytest.approx(at_x, abs=1e-9)
    assert weights @ y[corners] == pytest.approx(at_y, abs=1e-9)
    # A zone drawn between the middle ticks, as read off the picture: it has area.
    (x0, x1), (y0, y1) = (sorted(v for _, v in t)[1:3] for t in (x_ticks, y_ticks))
    zone = {"name": "read", "outer": {"x": [x0, x1, x1, x0], "y": [y0, y0, y1, y1]}}
    measured = await flatten(client, name, {**params, "zones": [zone]}, endpoint="/v1/measure")
    assert measured.status_code == 200, measured.text
    assert measured.json()["zones"][0]["area"] > 0
