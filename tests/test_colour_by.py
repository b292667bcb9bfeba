"""Pictures that show where the map can be trusted (``colour_by``): each triangle in the
colour of its distortion, a colour bar with the measure's p50 and p95, flagged triangles in
their own colours on top, the same colours on the GLB's vertices, and large regions whose
raster carries the colours."""

from __future__ import annotations

import io
import json
import re
import struct

import numpy as np
import pytest
import trimesh
from PIL import Image

from fixtures.meshes import subdivided_ply
from service.outputs.colours import STEPS, ColourBy, palette
from service.outputs.lookup import read_lookup
from service.samples import SAMPLES
from transforms import Chart, Frame, PoleCap, flatten_region
from transforms.metrics import weighted_quantile
from transforms.region import region_face_distortion

from .conftest import load_sample
from .test_api import SCALP, problem

pytestmark = pytest.mark.anyio

NAME = "fsaverage-head.ply"
PARAMS = {**SCALP[NAME], "image_width": 1000, "image_height": 700}


async def picture(client, params: dict, data: bytes | None = None, name: str = NAME):
    form = {"mesh": (name, SAMPLES[NAME].path.read_bytes() if data is None else data)}
    response = await client.post("/v1/flatten", files=form, data={"params": json.dumps(params)})
    assert response.status_code == 200, response.text
    return response


def distortion_of_scalp(measure: str) -> tuple[np.ndarray, np.ndarray]:
    """The scalp's per-face factor of ``measure`` (region order) and its faces' areas."""
    vertices, faces = load_sample(NAME)
    region = SCALP[NAME]
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - centre
    inside = directions[:, 2] / np.linalg.norm(directions, axis=1) >= np.cos(np.radians(70))
    assert region["region"]["cone"]["half_angle_deg"] == 70
    frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], centre)
    chart = Chart.distorted(PoleCap.from_sigma(0.3))
    flat = flatten_region(vertices, faces[inside], frame, chart)
    found = region_face_distortion(vertices, flat, frame, chart)
    values = getattr(found, measure)
    values = np.exp(values) if measure == "area" else values
    return values, found.weights


@pytest.mark.parametrize("measure", ["isometric", "conformal", "area"])
async def test_each_pixel_has_the_colour_of_its_triangles_distortion(client, measure):
    params = {**PARAMS, "colour_by": measure, "output": "png"}
    image = np.asarray(Image.open(io.BytesIO((await picture(client, params)).content)))
    lookup = await client.post(
        "/v1/transfer",
        files={"mesh": (NAME, SAMPLES[NAME].path.read_bytes())},
        data={"params": json.dumps({**PARAMS, "output": "face_ids"})},
    )
    ids, _ = read_lookup(lookup.content)
    flat = (await picture(client, PARAMS)).json()
    position = {face: k for k, face in enumerate(flat["faces"]["ids"])}
    values, weights = distortion_of_scalp(measure)
    top = max(weighted_quantile(values, weights, 0.99), 1.01)
    expected = palette()[
        np.minimum((np.log(values) / np.log(top) * STEPS).astype(int).clip(0), STEPS - 1)
    ]
    held = np.argwhere(ids >= 0)
    sample = held[np.random.default_rng(1).choice(len(held), 2000, replace=False)]
    rows, columns = sample.T
    faces = np.array([position[f] for f in ids[rows, columns]])
    # The boundary (drawn on top) covers a few pixels; every other pixel is its face's colour.
    matches = (image[rows, columns] == expected[faces]).all(axis=1)
    assert matches.mean() > 0.97, matches.mean()


async def test_the_colour_bar_names_the_measure_and_marks_p50_and_p95(client):
    svg = (await picture(client, {**PARAMS, "colour_by": "isometric", "output": "svg"})).text
    values, weights = distortion_of_scalp("isometric")
    bar = re.search(r'<g class="colour-bar">.*?</g>', svg, re.S).group(0)
    assert "isometric distortion" in bar and "linearGradient" in bar
    assert f"p50 {weighted_quantile(values, weights, 0.5):.3g}" in bar
    assert f"p95 {weighted_quantile(values, weights, 0.95):.3g}" in bar
    # Triangles one by one, a path for each colour, stroked alike.
    assert len(re.findall(r'class="triangles colour-\d+"', svg)) > 20
    plain = (await picture(client, {**PARAMS, "output": "svg"})).text
    assert "colour-bar" not in plain and 'class="triangles label-1"' in plain


async def test_flagged_triangles_keep_their_colours_over_the_distortion(client):
    # Seen from near the forehead, some of the scalp folds and is seen from behind.
    params = {
        **PARAMS,
        "center": [0, 80, 40],
        "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70, "apex": [1.3, -12.5, -32.3]}},
        "colour_by": "conformal",
        "output": "svg",
    }
    svg = (await picture(client, params)).text
    flagged = re.findall(r'class="triangles label-(\d+)"', svg)
    assert {"4", "5"} & set(flagged), flagged  # back-facing, folded
    # In the PNG, the pixels of folded triangles are the folded colour, not the measure's
    # (but for the outlines and boundary drawn over them).
    png = (await picture(client, {**params, "output": "png"})).content
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    unpainted = {k: v for k, v in params.items() if k != "colour_by"}
    lookup = await client.post(
        "/v1/transfer",
        files={"mesh": (NAME, SAMPLES[NAME].path.read_bytes())},
        data={"params": json.dumps({**unpainted, "output": "face_ids"})},
    )
    ids, _ = read_lookup(lookup.content)
    folded = (await picture(client, {**params, "output": "json"})).json()["validation"]
    under = np.isin(ids, folded["folded_faces"])
    assert under.sum() > 500
    assert (image[under] == (0xD5, 0x5E, 0x00)).all(axis=1).mean() > 0.9


async def test_the_glb_carries_the_colours_on_its_vertices(client):
    coloured = (
        await picture(client, {**PARAMS, "colour_by": "isometric", "output": "glb"})
    ).content
    scene = trimesh.load(io.BytesIO(coloured), file_type="glb", process=False)
    mesh = next(iter(scene.geometry.values()))
    length = struct.unpack_from("<I", coloured, 12)[0]
    document = json.loads(coloured[20 : 20 + length])
    primitive = document["meshes"][0]["primitives"][0]
    accessor = document["accessors"][primitive["attributes"]["COLOR_0"]]
    assert accessor["type"] == "VEC3" and accessor["count"] == len(mesh.vertices)
    assert document["asset"]["extras"]["meshflat"]["colour_by"]["measure"] == "isometric"
    plain = (await picture(client, {**PARAMS, "output": "glb"})).content
    length = struct.unpack_from("<I", plain, 12)[0]
    assert (
        "COLOR_0"
        not in json.loads(plain[20 : 20 + length])["meshes"][0]["primitives"][0]["attributes"]
    )


def glb_floats(glb: bytes, attribute: str) -> np.ndarray:
    """(n, k) float32: a float attribute of the GLB's first primitive, from its BIN chunk."""
    length = struct.unpack_from("<I", glb, 12)[0]
    document = json.loads(glb[20 : 20 + length])
    accessor = document["accessors"][
        document["meshes"][0]["primitives"][0]["attributes"][attribute]
    ]
    view = document["bufferViews"][accessor["bufferView"]]
    assert accessor["componentType"] == 5126 and view.get("byteStride") in (None, 0)
    width = {"VEC3": 3, "VEC4": 4}[accessor["type"]]
    start = 20 + length + 8 + view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    return np.frombuffer(glb, "<f4", accessor["count"] * width, start).reshape(-1, width)


async def test_the_glb_vertex_colours_are_their_faces_colours_weighed_by_area(client):
    glb = (await picture(client, {**PARAMS, "colour_by": "isometric", "output": "glb"})).content
    flat = (await picture(client, PARAMS)).json()
    assert flat["validation"]["folded_faces"] == flat["validation"]["backfacing_faces"] == []
    values, _ = distortion_of_scalp("isometric")  # no flagged face: all in the measure's colour
    top = max(weighted_quantile(values, distortion_of_scalp("isometric")[1], 0.99), 1.01)
    steps = np.minimum((np.log(values) / np.log(top) * STEPS).astype(int).clip(0), STEPS - 1)
    face_rgb = palette()[steps] / 255.0
    vertices, _ = load_sample(NAME)
    ids = np.array(flat["vertices"]["ids"])
    points = vertices[ids]
    local = np.full(len(vertices), -1)
    local[ids] = np.arange(len(ids))
    corners = local[np.array(flat["faces"]["vertices"])]  # the file's vertex ids, as rows
    areas = np.linalg.norm(
        np.cross(
            points[corners[:, 1]] - points[corners[:, 0]],
            points[corners[:, 2]] - points[corners[:, 0]],
        ),
        axis=1,
    )
    weighed = np.zeros((len(points), 3))
    total = np.zeros(len(points))
    np.add.at(weighed, corners.ravel(), np.repeat(face_rgb * areas[:, None], 3, axis=0))
    np.add.at(total, corners.ravel(), np.repeat(areas, 3))
    srgb = weighed / total[:, None]
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(glb_floats(glb, "POSITION"), points, atol=1e-4)
    np.testing.assert_allclose(glb_floats(glb, "COLOR_0"), linear, atol=1e-6)


async def test_a_large_region_shows_its_colours_in_a_bounded_svg(client):
    data = subdivided_ply(NAME, 3)  # 260k faces; the scalp about 100k, beyond the outline limit
    params = {**PARAMS, "colour_by": "isometric"}
    png = await picture(client, {**params, "output": "png"}, data)
    image = np.asarray(Image.open(io.BytesIO(png.content)))
    plot = image[60:600, 80:720].reshape(-1, 3)
    colours = {tuple(rgb) for rgb in plot[::7]}
    assert len(colours) > 60  # many colours, not one flat fill
    svg = (await picture(client, {**params, "output": "svg"}, data)).text
    assert 'class="fill colour-' in svg and "colour-bar" in svg
    # One run at most a 2 x 2 cell of the plot: the fill is bounded by the canvas.
    runs = sum(
        path.count("M") for path in re.findall(r'class="fill [^"]*" fill="[^"]*" d="([^"]*)"', svg)
    )
    assert runs <= (1000 - 340) * (700 - 144) / 4


async def test_an_unknown_measure_is_refused(client):
    form = {"mesh": (NAME, SAMPLES[NAME].path.read_bytes())}
    fields = {"params": json.dumps({**PARAMS, "colour_by": "stretch"})}
    body = problem(await client.post("/v1/flatten", files=form, data=fields), 422)
    assert "colour_by" in body["detail"] and all(m.value in body["detail"] for m in ColourBy)


def test_a_plane_cuts_a_flat_grid_along_its_line():
    from transforms.traces import grid_offsets, plane_traces

    from .conftest import grid_mesh

    vertices, faces = grid_mesh(np.linspace(0, 4, 9), np.linspace(0, 3, 7), 0.0)
    on_map = vertices[:, :2] * 2.0  # the map: the grid scaled
    segments = plane_traces(vertices, faces, on_map, [1, 0, 0], [1.25, 2.0])
    np.testing.assert_allclose(np.sort(np.unique(segments[..., 0])), [2.5, 4.0])
    for x in (2.5, 4.0):  # each line whole, from y 0 to 6 on the map, no piece twice
        mine = segments[np.isclose(segments[:, 0, 0], x)]
        assert np.isclose(np.abs(mine[:, 1, 1] - mine[:, 0, 1]).sum(), 6.0)
    np.testing.assert_allclose(grid_offsets(vertices, [0, 1, 0], 3), [0.5, 1.5, 2.5])


async def test_the_reference_grid_is_drawn_and_named(client):
    params = {**PARAMS, "grid_lines": 6, "output": "svg"}
    svg = (await picture(client, params)).text
    grid = re.search(r'<path class="grid"[^>]* d="([^"]*)"', svg).group(1)
    assert grid.count("M") > 100 and "grid: planes across local X and Z" in svg
    assert 'class="grid"' not in (await picture(client, {**PARAMS, "output": "svg"})).text


async def test_odd_regions_still_get_their_pictures(client):
    # One face (its picture has nothing but it), and the whole head, whose seam and singular
    # point triangles wrap round the map: the grid does not cross the map through them.
    one = {**PARAMS, "region": {"faces": [0]}, "colour_by": "isometric", "output": "png"}
    await picture(client, one)
    whole = {**PARAMS, "region": None, "grid_lines": 8, "output": "svg", "colour_by": "area"}
    svg = (await picture(client, whole)).text
    grid = re.search(r'<path class="grid"[^>]* d="([^"]*)"', svg).group(1)
    ends = np.array([float(v) for v in re.findall(r"-?\d+\.\d", grid)]).reshape(-1, 4)
    lengths = np.hypot(ends[:, 2] - ends[:, 0], ends[:, 3] - ends[:, 1])
    assert lengths.max() < 60, lengths.max()
