"""/v1/flatten's other forms: the GLB (checked by the Khronos glTF-Validator), the SVG and
PNG pictures of the map, and the choice among them."""

from __future__ import annotations

import io
import json
import struct
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from PIL import Image

from service.capabilities.region import pictures
from service.forms import choose_output
from service.outputs import Output
from service.problems import Problem
from service.samples import SAMPLES

from .test_api import SCALP, flatten, problem
from .tools import node_tool

pytestmark = pytest.mark.anyio

#: A region of every bundled sample: the scalps, and Nefertiti whole (flagged faces).
REGIONS = {**SCALP, "nefertiti-lowres.obj": {"rotation": "identity", "sigma": 0.3}}
SVG = "{http://www.w3.org/2000/svg}"


def read_glb(data: bytes) -> tuple[dict, bytes]:
    """The JSON document and the binary chunk of a GLB."""
    magic, version, length = struct.unpack_from("<III", data)
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    json_length, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A
    document = json.loads(data[20 : 20 + json_length])
    bin_length, bin_type = struct.unpack_from("<II", data, 20 + json_length)
    assert bin_type == 0x004E4942
    start = 28 + json_length
    return document, data[start : start + bin_length]


def accessor(document: dict, binary: bytes, index: int) -> np.ndarray:
    a = document["accessors"][index]
    view = document["bufferViews"][a["bufferView"]]
    dtype = {5126: np.float32, 5125: np.uint32}[a["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[a["type"]]
    values = np.frombuffer(binary, dtype, a["count"] * width, view["byteOffset"])
    return values.reshape(a["count"], width) if width > 1 else values


async def both(client, name, params, output):
    """The JSON answer and the ``output`` answer of one request."""
    as_json = (await flatten(client, name, params)).json()
    response = await flatten(client, name, {**params, "output": output})
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == Output(output).media_type
    return as_json, response


@pytest.mark.parametrize("name", list(REGIONS))
async def test_glb_holds_the_region_with_its_uvs_and_ids(client, name, tmp_path):
    as_json, response = await both(client, name, REGIONS[name], "glb")
    document, binary = read_glb(response.content)
    primitive = document["meshes"][0]["primitives"][0]
    positions = accessor(document, binary, primitive["attributes"]["POSITION"])
    uv = accessor(document, binary, primitive["attributes"]["TEXCOORD_0"])
    vertex_ids = accessor(document, binary, primitive["attributes"]["_VERTEX_ID"])
    triangles = accessor(document, binary, primitive["indices"]).reshape(-1, 3)
    extras = document["asset"]["extras"]["meshflat"]
    face_ids = accessor(document, binary, extras["face_ids_accessor"])
    ids = np.asarray(as_json["vertices"]["ids"])
    assert np.array_equal(vertex_ids, ids)
    assert np.array_equal(face_ids, as_json["faces"]["ids"])
    # Triangle k is file face faces.ids[k], through the vertex ids.
    assert np.array_equal(ids[triangles], as_json["faces"]["vertices"])
    assert len(positions) == len(ids) and uv.min() >= 0 and uv.max() <= 1
    assert extras["params"] == as_json["params"]
    assert extras["validation"]["seam_free"] == as_json["validation"]["seam_free"]
    assert extras["validation"]["backfacing_faces"] == len(
        as_json["validation"]["backfacing_faces"]
    )
    # The UVs are the layout, by the affine map in the extras.
    u = extras["uv"]
    phi, theta = np.asarray(as_json["vertices"]["phi"]), np.asarray(as_json["vertices"]["theta"])
    assert np.allclose(uv[:, 0] / u["scale"] + u["x_min"], phi, atol=1e-5)
    assert np.allclose(u["s_sign"] * (uv[:, 1] / u["scale"] + u["s_min"]), theta, atol=1e-5)
    # And the Khronos validator finds no error and no warning.
    path = tmp_path / "region.glb"
    path.write_bytes(response.content)
    run = subprocess.run(
        [*node_tool("validate-gltf.mjs"), str(path)], capture_output=True, text=True, check=True
    )
    (report,) = json.loads(run.stdout)
    assert report["issues"]["numErrors"] == 0, report
    assert report["issues"]["numWarnings"] == 0, report


async def test_mercator_uvs_run_down_with_theta(client):
    params = {**SCALP["fsaverage-head.ply"], "layout": "mercator"}
    as_json, response = await both(client, "fsaverage-head.ply", params, "glb")
    document, binary = read_glb(response.content)
    primitive = document["meshes"][0]["primitives"][0]
    uv = accessor(document, binary, primitive["attributes"]["TEXCOORD_0"])
    u = document["asset"]["extras"]["meshflat"]["uv"]
    assert u["s_sign"] == -1.0 and u["layout"] == "mercator"
    y = np.asarray(as_json["vertices"]["y"])
    assert np.allclose(-(uv[:, 1] / u["scale"] + u["s_min"]), y, atol=1e-5)
    theta = np.asarray(as_json["vertices"]["theta"])
    assert np.corrcoef(uv[:, 1], theta)[0, 1] > 0.99


@pytest.mark.parametrize("name", list(REGIONS))
async def test_svg_is_a_well_formed_map_with_a_legend(client, name):
    as_json, response = await both(client, name, REGIONS[name], "svg")
    root = ET.fromstring(response.content)
    assert root.tag == f"{SVG}svg" and root.get("width") == "1200" and root.get("height") == "800"
    text = " ".join(t.text or "" for t in root.iter(f"{SVG}text"))
    faces = len(as_json["faces"]["ids"])
    assert f"region: {faces:,} triangles" in text and "x = phi (layout units, rad)" in text
    assert "sigma 0.3" in text  # the caption
    backfacing = len(as_json["validation"]["backfacing_faces"])
    if backfacing:
        assert f"back-facing: {backfacing:,}" in text
        assert root.find(f".//{SVG}path[@class='marks label-5']") is not None
        # A triangle both back-facing and folded is drawn as folded, and the legend says so.
        v = as_json["validation"]
        doubly = len(set(v["backfacing_faces"]) & set(v["folded_faces"]))
        if doubly:
            assert f"back-facing: {backfacing:,} ({doubly:,} drawn as folded)" in text
    has_boundary = root.find(f".//{SVG}path[@class='boundary']") is not None
    assert has_boundary == (as_json["validation"]["boundary_loops"] > 0)


async def test_seam_and_singular_points_are_drawn_where_they_fall_in_view(client):
    # Nefertiti whole: the region surrounds the centre, so the seam and both singular
    # points fall inside the map.
    _, response = await both(client, "nefertiti-lowres.obj", {}, "svg")
    root = ET.fromstring(response.content)
    assert len(root.findall(f".//{SVG}line[@class='seam']")) == 2
    assert root.find(f".//{SVG}line[@class='singular north']") is not None
    # A scalp keeps both far away: neither is drawn.
    _, response = await both(client, "fsaverage-head.ply", SCALP["fsaverage-head.ply"], "svg")
    root = ET.fromstring(response.content)
    assert not root.findall(f".//{SVG}line[@class='seam']")
    assert not root.findall(f".//{SVG}line[@class='singular north']")


@pytest.mark.parametrize("size", [(1200, 800), (640, 480)])
async def test_png_decodes_at_the_size_asked_for(client, size):
    width, height = size
    params = {**SCALP["lee-perry-smith.glb"], "image_width": width, "image_height": height}
    _, response = await both(client, "lee-perry-smith.glb", params, "png")
    image = Image.open(io.BytesIO(response.content))
    image.load()
    assert image.format == "PNG" and image.size == (width, height)
    pixels = np.asarray(image.convert("RGB"))
    # The region's fill colour covers a good part of the picture.
    assert (pixels == [0xCF, 0xE3, 0xF2]).all(axis=2).mean() > 0.05


async def test_accept_header_chooses_the_form_and_params_output_wins(client):
    name, params = "fsaverage-head.ply", SCALP["fsaverage-head.ply"]
    data = SAMPLES[name].path.read_bytes()
    files = {"mesh": (name, data)}

    async def post(accept, output=None):
        body = {**params, "output": output} if output else params
        headers = {"Accept": accept} if accept else {}
        return await client.post(
            "/v1/flatten", files=files, data={"params": json.dumps(body)}, headers=headers
        )

    for accept, media_type in [
        ("image/png", "image/png"),
        ("image/svg+xml, image/png;q=0.5", "image/svg+xml"),
        ("model/gltf-binary", "model/gltf-binary"),
        ("*/*", "application/json"),
    ]:
        response = await post(accept)
        assert response.status_code == 200 and response.headers["content-type"] == media_type
    response = await post("image/png", output="json")
    assert response.headers["content-type"] == "application/json"
    body = problem(await post("text/html"), 406, "Accept")
    assert "text/html" in body["detail"] and "image/png" in body["detail"]


@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_accept_quality_values_and_wildcards():
    assert choose_output(None, None) is Output.JSON
    assert choose_output("image/*", None) is Output.SVG
    assert choose_output("image/*;q=0.9, image/png", None) is Output.PNG
    assert choose_output("*/*;q=0.1, model/gltf-binary", None) is Output.GLB
    assert choose_output("application/json;q=0, */*", None) is Output.GLB
    with pytest.raises(Problem):
        choose_output("image/png;q=0", None)


async def test_a_bad_output_or_image_size_names_the_field(client):
    params = SCALP["fsaverage-head.ply"]
    for extra, field in [
        ({"output": "jpeg"}, "params.output"),
        ({"image_width": 10}, "params.image_width"),
        ({"image_height": 100_000}, "params.image_height"),
    ]:
        problem(await flatten(client, "fsaverage-head.ply", {**params, **extra}), 422, field)


async def test_vertex_ids_beyond_float32_refuse_a_glb(client, monkeypatch):
    monkeypatch.setattr(pictures, "FLOAT32_EXACT", 100)
    params = {**SCALP["fsaverage-head.ply"], "output": "glb"}
    body = problem(await flatten(client, "fsaverage-head.ply", params), 422, "params.output")
    assert "float32" in body["detail"] and body["indices"]


async def test_a_large_region_is_drawn_with_a_decimated_fill(client):
    from .conftest import grid_mesh

    axis = np.linspace(-1.0, 1.0, 110)
    vertices, faces = grid_mesh(axis, axis, 1.0)  # 23,762 triangles: over VECTOR_TRIANGLES
    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in vertices)
    obj += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    params = {"center": [0, 0, 0], "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]}}
    response = await flatten(client, "", {**params, "output": "svg"}, obj.encode(), "grid.obj")
    assert response.status_code == 200, response.text
    root = ET.fromstring(response.content)
    assert root.find(f".//{SVG}path[@class='fill label-1']") is not None
    assert root.find(f".//{SVG}path[@class='triangles label-1']") is None
    assert len(response.content) < 2_000_000
